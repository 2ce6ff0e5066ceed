//! The MCAP trajectory reader: what `sdem inspect`, `sdem render` (frame decoding, without
//! drawing), `sdem plot` (the macro rows) and `sdem resume --mcap` (the linear scan of a
//! possibly unfinished log) read. The readers take a path, so the input is written to a file
//! of this process in the temporary directory first.
#![no_main]

use libfuzzer_sys::fuzz_target;
use sdem::output::mcap::{Trajectory, scan_log};
use std::path::PathBuf;
use std::sync::OnceLock;

fn path() -> &'static PathBuf {
    static P: OnceLock<PathBuf> = OnceLock::new();
    P.get_or_init(|| {
        let dir = if std::path::Path::new("/dev/shm").is_dir() {
            PathBuf::from("/dev/shm")
        } else {
            std::env::temp_dir()
        };
        dir.join(format!("sdem-fuzz-{}.mcap", std::process::id()))
    })
}

fuzz_target!(|data: &[u8]| {
    let path = path();
    std::fs::write(path, data).expect("writing the input to a temporary file");
    // `sdem resume --mcap`: the linear scan of the old log.
    let _ = scan_log(path, |_, _| Ok(true));
    let Ok(log) = Trajectory::open(path) else {
        return;
    };
    // `sdem inspect`
    let _ = log.sizes();
    let _ = log.compression();
    let _ = log.span();
    let _ = log.solver();
    let frames = log.frame_count();
    // `sdem render`: first and last frame, by step, at the jamming point
    if frames > 0 {
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
    // `sdem plot` of a log, and the scenario stored in it
    let _ = log.macro_rows();
    let _ = log.scenario();
});
