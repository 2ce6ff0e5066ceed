//! Inputs that crashed a fuzz target (`fuzz/`, `tools/fuzz.sh`, docs/robustness.md), kept as
//! files under `tests/data/fuzz/<target>/` and replayed here through the calls of that target:
//! each must end in an error or a value, never a panic; and the specific defect of each is
//! checked where a release build would not panic on it (integer overflow wraps there).

use sdem::output::mcap::{Trajectory, scan_log};
use std::path::{Path, PathBuf};
use std::process::Command;

fn inputs(target: &str) -> Vec<PathBuf> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/fuzz")
        .join(target);
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .map(|d| d.map(|e| e.unwrap().path()).collect())
        .unwrap_or_default();
    files.sort();
    files
}

/// What the `mcap` fuzz target calls (`sdem inspect`, `render`'s decoding, `plot`, `resume
/// --mcap`'s scan).
fn read_log_like_the_fuzz_target(path: &Path) {
    let _ = scan_log(path, |_, _| Ok(true));
    let Ok(log) = Trajectory::open(path) else {
        return;
    };
    let _ = log.sizes();
    let _ = log.compression();
    let _ = log.span();
    let _ = log.solver();
    if log.frame_count() > 0 {
        let _ = log.frame(0);
        let _ = log.frame(-1);
        if let Ok((step, _)) = log.frame_header(-1) {
            let _ = log.frame_at_step(step);
        }
    }
    if let Some(step) = log
        .summary_info("jamming_step")
        .and_then(|s| s.parse().ok())
    {
        let _ = log.frame_at_step(step);
    }
    let _ = log.macro_rows();
    let _ = log.scenario();
}

#[test]
#[cfg_attr(
    debug_assertions,
    ignore = "mcap 0.26.0 overflows on one input when built with overflow checks (see docs/robustness.md); release wraps"
)]
fn mcap_inputs_that_crashed_the_fuzzer_do_not_panic() {
    let files = inputs("mcap");
    assert!(!files.is_empty());
    for path in &files {
        let outcome = std::panic::catch_unwind(|| read_log_like_the_fuzz_target(path));
        assert!(outcome.is_ok(), "panic on {}", path.display());
        // And `sdem inspect` on it: a report or an error naming the file, never a panic.
        let out = Command::new(env!("CARGO_BIN_EXE_sdem"))
            .arg("inspect")
            .arg(path)
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(!stderr.contains("panicked"), "{}: {stderr}", path.display());
        assert!(
            out.status.success() || stderr.contains(&path.display().to_string()),
            "{}: {stderr}",
            path.display()
        );
    }
}

/// Found by the `mcap` target: chunk indexes whose sizes add up past 2^64 (`Trajectory::sizes`
/// summed them with `+`: a panic with overflow checks, a wrapped, wrong total without). The
/// totals saturate.
#[test]
fn chunk_sizes_beyond_u64_saturate() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/fuzz/mcap/chunk_sizes_overflow.mcap");
    let bytes = std::fs::read(&path).unwrap();
    let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
    let total = |f: fn(&mcap::records::ChunkIndex) -> u64| {
        summary
            .chunk_indexes
            .iter()
            .try_fold(0u64, |a, c| a.checked_add(f(c)))
    };
    let compressed = total(|c| c.compressed_size);
    let uncompressed = total(|c| c.uncompressed_size);
    // The input's point: one of the totals does not fit in a u64.
    assert!(compressed.is_none() || uncompressed.is_none());
    let sizes = Trajectory::open(&path).unwrap().sizes();
    assert_eq!(sizes.compressed_bytes, compressed.unwrap_or(u64::MAX));
    assert_eq!(sizes.uncompressed_bytes, uncompressed.unwrap_or(u64::MAX));
}

/// Found by the `mcap` target, in the `mcap` crate (0.26.0): a record of an uncompressed chunk
/// that runs past the chunk's end makes its linear reader subtract with overflow. Built as in
/// release (wrapping), the read of `sdem resume --mcap` stops with the log's readable part and
/// the reason, or an error naming the file; never a panic.
#[test]
#[cfg_attr(
    debug_assertions,
    ignore = "mcap 0.26.0 overflows here when built with overflow checks; release wraps"
)]
fn a_chunk_record_past_the_chunk_end_stops_the_scan() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/fuzz/mcap/chunk_record_overruns_chunk.mcap");
    match scan_log(&path, |_, _| Ok(true)) {
        Ok(scan) => assert!(
            !scan.finished && scan.stopped.is_some(),
            "read as a whole log: {:?}",
            scan.stopped
        ),
        Err(e) => assert!(
            e.to_string().contains("chunk_record_overruns_chunk.mcap"),
            "{e}"
        ),
    }
}

/// What the `sample_file` fuzz target calls: `Scenario::load_sample`'s parse and packing check
/// against `scenarios/compaction30_prepare.ron`.
fn check_sample_like_the_fuzz_target(text: &str) -> Result<(), String> {
    let s = sdem::scenario::Scenario::parse(
        include_str!("../scenarios/compaction30_prepare.ron"),
        "compaction30_prepare.ron",
    )
    .unwrap();
    let sample = sdem::sample::file::parse_grains(text, "fuzz.csv").map_err(|e| e.to_string())?;
    sdem::sample::file::check_packing(
        "fuzz.csv",
        &sample,
        s.sample.bounds(),
        &s.secant_law(),
        s.contact.resolution_deg,
    )
    .map_err(|e| e.to_string())
}

/// Found by the `sample_file` target: grains with radii of 1e-45 a millimetre apart made the
/// neighbour grid's column count overflow (`usize::MAX + 1`: a panic with overflow checks; in
/// release 0 columns, then an index out of bounds). The count saturates (and is capped).
#[test]
fn sample_inputs_that_crashed_the_fuzzer_do_not_panic() {
    let files = inputs("sample_file");
    assert!(!files.is_empty());
    for path in &files {
        let text = std::fs::read_to_string(path).unwrap();
        let outcome = std::panic::catch_unwind(|| check_sample_like_the_fuzz_target(&text));
        assert!(outcome.is_ok(), "panic on {}", path.display());
    }
}
