//! Eight lanes of four points each read by AVX-512 gathers (eight `vgatherdpd`, one a
//! coordinate) against eight 64-byte row loads and their 8 x 8 transpose, as the polygon kernel
//! reads its nodes (issue #16, forty-fifth session: gathers some six times slower on the Ice
//! Lake machine, most likely the microcode's mitigation of Gather Data Sampling). Standalone,
//! not part of the crate; needs AVX-512:
//!   rustc -O -C target-cpu=native tools/gather_microbench.rs -o /tmp/gather_microbench
//!   taskset -c 1 /tmp/gather_microbench
use std::arch::x86_64::*;
use std::time::Instant;

/// The eight lanes' rows `table[k[l]..k[l] + 8]` as eight vectors of one coordinate each.
type Read = unsafe fn(&[f64], __m256i) -> [__m512d; 8];

#[target_feature(enable = "avx512f,avx512vl")]
unsafe fn by_gathers(table: &[f64], k: __m256i) -> [__m512d; 8] {
    std::array::from_fn(|c| unsafe { _mm512_i32gather_pd::<8>(k, table.as_ptr().add(c)) })
}

#[target_feature(enable = "avx512f,avx512vl")]
unsafe fn by_rows(table: &[f64], k: __m256i) -> [__m512d; 8] {
    let k: [i32; 8] = unsafe { std::mem::transmute(k) };
    let r: [__m512d; 8] =
        std::array::from_fn(|l| unsafe { _mm512_loadu_pd(table.as_ptr().add(k[l] as usize)) });
    // Rows to columns in three rounds of shuffles, as the kernel's `load_quads`.
    let pairs: [__m512d; 8] = std::array::from_fn(|p| {
        let (a, b) = (r[2 * (p / 2)], r[2 * (p / 2) + 1]);
        if p % 2 == 0 {
            _mm512_unpacklo_pd(a, b)
        } else {
            _mm512_unpackhi_pd(a, b)
        }
    });
    let quads: [__m512d; 8] = std::array::from_fn(|q| {
        let (a, b) = (
            pairs[(q % 2) + 4 * (q / 4)],
            pairs[(q % 2) + 2 + 4 * (q / 4)],
        );
        if (q / 2) % 2 == 0 {
            _mm512_shuffle_f64x2::<0b10_00_10_00>(a, b)
        } else {
            _mm512_shuffle_f64x2::<0b11_01_11_01>(a, b)
        }
    });
    std::array::from_fn(|c| {
        let (a, b) = (quads[c % 4], quads[c % 4 + 4]);
        if c < 4 {
            _mm512_shuffle_f64x2::<0b10_00_10_00>(a, b)
        } else {
            _mm512_shuffle_f64x2::<0b11_01_11_01>(a, b)
        }
    })
}

/// Nanoseconds a call of `read` over `starts` eight at a time, `repeats` times, and a sum of
/// what it read (so that nothing is left out).
#[target_feature(enable = "avx512f,avx512vl")]
unsafe fn time(read: Read, table: &[f64], starts: &[i32], repeats: usize) -> (f64, f64) {
    let clock = Instant::now();
    let mut sum = _mm512_setzero_pd();
    for repeat in 0..repeats {
        for lanes in starts.chunks_exact(8) {
            let k = unsafe { _mm256_loadu_si256(lanes.as_ptr().cast()) };
            let k = _mm256_add_epi32(k, _mm256_set1_epi32((repeat & 7) as i32));
            for v in unsafe { read(table, k) } {
                sum = _mm512_add_pd(sum, v);
            }
        }
    }
    let calls = (repeats * starts.len() / 8) as f64;
    (
        clock.elapsed().as_secs_f64() / calls * 1e9,
        _mm512_reduce_add_pd(sum),
    )
}

fn main() {
    assert!(
        std::arch::is_x86_feature_detected!("avx512f"),
        "needs AVX-512"
    );
    let table: Vec<f64> = (0..3000).map(f64::from).collect();
    let mut state = 12345u64;
    let starts: Vec<i32> = (0..4096)
        .map(|_| {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1);
            ((state >> 33) % 2000) as i32
        })
        .collect();
    for _ in 0..3 {
        // SAFETY: the processor has AVX-512 (asserted above).
        let (gathers, a) = unsafe { time(by_gathers, &table, &starts, 2000) };
        let (rows, b) = unsafe { time(by_rows, &table, &starts, 2000) };
        assert_eq!(a, b, "both read the same values");
        println!("eight gathers: {gathers:.2} ns a call; rows and transpose: {rows:.2} ns a call");
    }
}
