//! Eight lanes of four points each read by AVX-512 gathers (eight `vgatherdpd`, one a
//! coordinate) against eight 64-byte row loads and their 8 x 8 transpose, as the polygon kernel
//! reads its nodes (issue #16, forty-fifth session: gathers some six times slower on the Ice
//! Lake machine, most likely the microcode's mitigation of Gather Data Sampling). Standalone,
//! not part of the crate; needs AVX-512:
//!   rustc -O -C target-cpu=native tools/gather_microbench.rs -o /tmp/gather_microbench
//!   taskset -c 1 /tmp/gather_microbench
use std::arch::x86_64::*;
use std::time::Instant;
#[target_feature(enable = "avx512f,avx512vl")]
unsafe fn gathers(table: &[f64], idx: &[i32], reps: usize) -> f64 {
    let mut acc = _mm512_setzero_pd();
    let n = idx.len() / 8;
    for r in 0..reps {
        for b in 0..n {
            let vi = _mm256_loadu_si256(idx.as_ptr().add(b * 8) as *const __m256i);
            let vi = _mm256_add_epi32(vi, _mm256_set1_epi32((r & 7) as i32));
            for c in 0..8 {
                let g = _mm512_i32gather_pd::<8>(vi, table.as_ptr().add(c));
                acc = _mm512_add_pd(acc, g);
            }
        }
    }
    let mut out = [0.0; 8];
    _mm512_storeu_pd(out.as_mut_ptr(), acc);
    out.iter().sum()
}
#[target_feature(enable = "avx512f,avx512vl")]
unsafe fn transposes(table: &[f64], idx: &[i32], reps: usize) -> f64 {
    let mut acc = _mm512_setzero_pd();
    let n = idx.len() / 8;
    for r in 0..reps {
        for b in 0..n {
            let vi = _mm256_loadu_si256(idx.as_ptr().add(b * 8) as *const __m256i);
            let vi = _mm256_add_epi32(vi, _mm256_set1_epi32((r & 7) as i32));
            let k: [i32; 8] = std::mem::transmute(vi);
            let rows: [__m512d; 8] = std::array::from_fn(|l| _mm512_loadu_pd(table.as_ptr().add(k[l] as usize)));
            let x01 = _mm512_unpacklo_pd(rows[0], rows[1]); let y01 = _mm512_unpackhi_pd(rows[0], rows[1]);
            let x23 = _mm512_unpacklo_pd(rows[2], rows[3]); let y23 = _mm512_unpackhi_pd(rows[2], rows[3]);
            let x45 = _mm512_unpacklo_pd(rows[4], rows[5]); let y45 = _mm512_unpackhi_pd(rows[4], rows[5]);
            let x67 = _mm512_unpacklo_pd(rows[6], rows[7]); let y67 = _mm512_unpackhi_pd(rows[6], rows[7]);
            for q in [[x01, x23, x45, x67], [y01, y23, y45, y67]] {
                let a = _mm512_shuffle_f64x2::<0b10_00_10_00>(q[0], q[1]);
                let b2 = _mm512_shuffle_f64x2::<0b11_01_11_01>(q[0], q[1]);
                let c = _mm512_shuffle_f64x2::<0b10_00_10_00>(q[2], q[3]);
                let d = _mm512_shuffle_f64x2::<0b11_01_11_01>(q[2], q[3]);
                let e = _mm512_shuffle_f64x2::<0b10_00_10_00>(a, c);
                let f = _mm512_shuffle_f64x2::<0b11_01_11_01>(a, c);
                let g = _mm512_shuffle_f64x2::<0b10_00_10_00>(b2, d);
                let h = _mm512_shuffle_f64x2::<0b11_01_11_01>(b2, d);
                acc = _mm512_add_pd(acc, _mm512_add_pd(_mm512_add_pd(e, f), _mm512_add_pd(g, h)));
            }
        }
    }
    let mut out = [0.0; 8];
    _mm512_storeu_pd(out.as_mut_ptr(), acc);
    out.iter().sum()
}
fn main() {
    let table: Vec<f64> = (0..3000).map(|i| i as f64).collect();
    let mut s = 12345u64;
    let idx: Vec<i32> = (0..4096).map(|_| { s = s.wrapping_mul(6364136223846793005).wrapping_add(1); ((s >> 33) % 2000) as i32 * 1 }).collect();
    let reps = 2000;
    for _ in 0..3 {
        let t = Instant::now(); let a = unsafe { gathers(&table, &idx, reps) }; let tg = t.elapsed().as_secs_f64();
        let t = Instant::now(); let b = unsafe { transposes(&table, &idx, reps) }; let tt = t.elapsed().as_secs_f64();
        let calls = (reps * idx.len() / 8) as f64;
        println!("gather8x8: {:.2} ns/call  transpose: {:.2} ns/call  ({} {})", tg / calls * 1e9, tt / calls * 1e9, a, b);
    }
}
