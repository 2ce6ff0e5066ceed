//! `sdem resume --mcap FILE` continues the interrupted run's trajectory log: the final file
//! holds exactly the messages of the uninterrupted run's log (every frame, every `/macro` row,
//! the same channels, scenario and metadata), whether the run was stopped cleanly or killed
//! (an unfinished log holding frames after the checkpoint); a damaged log is refused with a
//! clear error.

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use sdem::output::mcap::{McapSettings, Trajectory, scan_log};
use sdem::run::checkpoint::Checkpoint;
use sdem::run::{RunError, RunOptions, resume_run, run_scenario};
use sdem::scenario::Scenario;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

mod common;
use common::SMALL_COMPACTION as SMALL;

/// The two logs hold the same messages, and more than 50 frames.
fn assert_same_log(reference: &Path, other: &Path) {
    common::mcap::assert_same_log(reference, other, 51);
}

fn scenario() -> Scenario {
    common::small_compaction()
}

fn temp_dir(name: &str) -> common::TempDir {
    common::temp_dir("mcapres", name)
}

fn options(out: &Path, every: u64, log: &Path) -> RunOptions {
    RunOptions {
        mcap: Some(McapSettings::new(log)),
        ..common::checkpointed(out, every)
    }
}

/// A reference log of the uninterrupted run with checkpoints every `every` steps.
fn reference(dir: &Path, every: u64) -> (PathBuf, u64) {
    let log = dir.join("ref.mcap");
    let s = run_scenario(&scenario(), &options(&dir.join("ref"), every, &log)).unwrap();
    (log, s.steps)
}

fn resume(dir: &Path, log: &Path, stop_after: Option<u64>) -> Result<(), RunError> {
    let ckpt = dir.join("checkpoint.bin");
    let c = Checkpoint::read(&ckpt).unwrap();
    let mut opts = options(dir, c.checkpoint_every, log);
    opts.stop_after_step = stop_after;
    resume_run(&c, &ckpt, &opts).map(|_| ())
}

#[test]
fn stopped_then_resumed_log_is_the_uninterrupted_log() {
    let base = temp_dir("stop");
    let (reference, total) = reference(&base, 700);
    // A row step, off a row step, before the first frame, in the second phase; the last one
    // is stopped twice.
    for stops in [
        vec![1000],
        vec![1234],
        vec![1],
        vec![total - 500],
        vec![777, 2100],
    ] {
        let dir = base.join(format!("s{}", stops[0]));
        let log = dir.join("run.mcap");
        let mut opts = options(&dir, 700, &log);
        opts.stop_after_step = Some(stops[0]);
        let e = run_scenario(&scenario(), &opts).unwrap_err();
        assert!(matches!(e, RunError::Interrupted { .. }), "{e}");
        let stopped = Trajectory::open(&log).unwrap();
        assert_eq!(stopped.summary_info("status"), Some("interrupted"));
        for &next in &stops[1..] {
            let e = resume(&dir, &log, Some(next)).unwrap_err();
            assert!(matches!(e, RunError::Interrupted { .. }), "{e}");
            let t = Trajectory::open(&log).unwrap();
            assert_eq!(t.summary_info("status"), Some("interrupted"));
            let c = Checkpoint::read(&dir.join("checkpoint.bin")).unwrap();
            assert_eq!(t.frame_count() as u64, c.runner.macro_rows);
            assert!(t.frame_header(-1).unwrap().0 <= next);
        }
        resume(&dir, &log, None).unwrap();
        assert_same_log(&reference, &log);
        let tmp = dir.join("run.mcap.resume.tmp");
        assert!(!tmp.exists(), "{} left behind", tmp.display());
    }
    std::fs::remove_dir_all(&base).ok();
}

#[test]
fn a_missing_log_is_started_with_the_continued_part() {
    let base = temp_dir("missing");
    let dir = base.join("run");
    let mut opts = options(&dir, 700, &base.join("first.mcap"));
    opts.stop_after_step = Some(5000);
    assert!(run_scenario(&scenario(), &opts).is_err());
    let log = base.join("continued.mcap");
    resume(&dir, &log, None).unwrap();
    let t = Trajectory::open(&log).unwrap();
    assert_eq!(t.summary_info("status"), Some("complete"));
    assert_eq!(t.frame_header(0).unwrap().0, 5050);
    std::fs::remove_dir_all(&base).ok();
}

fn sdem() -> Command {
    Command::new(env!("CARGO_BIN_EXE_sdem"))
}

fn run_cli(args: &[&str]) -> std::process::Output {
    let out = sdem().args(args).output().unwrap();
    assert!(
        out.status.success(),
        "sdem {args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

#[test]
fn killed_run_log_is_continued_to_the_uninterrupted_log() {
    let base = temp_dir("kill");
    let scenario_path = base.join("small.ron");
    std::fs::write(&scenario_path, SMALL).unwrap();
    let scenario_path = scenario_path.to_str().unwrap();
    let reference = base.join("ref.mcap");
    let started = Instant::now();
    run_cli(&[
        "run",
        scenario_path,
        "--out",
        base.join("ref").to_str().unwrap(),
        "--mcap",
        reference.to_str().unwrap(),
        "--checkpoint-every",
        "1500",
        "--threads",
        "2",
        "--quiet",
    ]);
    let run_ms = started.elapsed().as_millis() as u64;
    let mut rng = ChaCha8Rng::seed_from_u64(
        std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .unwrap()
            .as_nanos() as u64,
    );
    let (mut cut, mut beyond) = (0, 0);
    // Up to 12 kills: on a loaded machine several in a row can land just after a checkpoint
    // (nothing logged beyond it); the loop stops after 3 once one has landed beyond.
    for attempt in 0..12 {
        if beyond > 0 && attempt >= 3 {
            break;
        }
        let dir = base.join(format!("run{attempt}"));
        let log = dir.join("run.mcap");
        let mut child = sdem()
            .args(["run", scenario_path, "--out", dir.to_str().unwrap()])
            .args([
                "--mcap",
                log.to_str().unwrap(),
                "--checkpoint-every",
                "1500",
            ])
            .args(["--threads", "2", "--quiet"])
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        let t0 = Instant::now();
        while !dir.join("checkpoint.bin").exists() {
            assert!(t0.elapsed() < Duration::from_secs(60), "no checkpoint");
            if child.try_wait().unwrap().is_some() {
                break;
            }
            std::thread::sleep(Duration::from_millis(2));
        }
        // Somewhere in the rest of the run (4 checkpoints in all).
        std::thread::sleep(Duration::from_millis(rng.random_range(0..run_ms * 3 / 4)));
        child.kill().unwrap();
        child.wait().unwrap();
        let ckpt = dir.join("checkpoint.bin");
        let c = Checkpoint::read(&ckpt).unwrap();
        if !c.complete {
            cut += 1;
            let scan = scan_log(&log, |_, _| Ok(true)).unwrap();
            assert!(!scan.finished, "a killed run's log is unfinished");
            let frames = scan.frames.len() as u64;
            assert!(
                frames >= c.runner.macro_rows,
                "the log lost frames of the checkpoint: {frames} < {}",
                c.runner.macro_rows
            );
            if frames > c.runner.macro_rows {
                beyond += 1;
            }
            eprintln!(
                "killed at checkpoint step {}: {} frames in the checkpoint, {frames} in the log",
                c.step, c.runner.macro_rows
            );
            let out = run_cli(&[
                "resume",
                ckpt.to_str().unwrap(),
                "--mcap",
                log.to_str().unwrap(),
                "--threads",
                "1",
                "--quiet",
            ]);
            let stderr = String::from_utf8_lossy(&out.stderr);
            assert!(stderr.contains("continuing the MCAP log"), "{stderr}");
            assert_same_log(&reference, &log);
        }
    }
    eprintln!("killed: {cut} runs, {beyond} with frames after the checkpoint in the log");
    assert!(cut > 0, "every run finished before it could be killed");
    assert!(beyond > 0, "no killed log held frames after its checkpoint");
    std::fs::remove_dir_all(&base).ok();
}

#[test]
fn damaged_or_foreign_logs_are_refused_with_a_clear_error() {
    let base = temp_dir("damaged");
    let dir = base.join("run");
    let log = dir.join("run.mcap");
    let stop = 4400;
    let mut opts = options(&dir, 700, &log);
    opts.stop_after_step = Some(stop);
    assert!(run_scenario(&scenario(), &opts).is_err());
    let good = std::fs::read(&log).unwrap();
    let ckpt = std::fs::read(dir.join("checkpoint.bin")).unwrap();
    let attempt = |bytes: &[u8]| -> Result<(), String> {
        std::fs::write(&log, bytes).unwrap();
        std::fs::write(dir.join("checkpoint.bin"), &ckpt).unwrap();
        // Resumed and stopped again one step later: the log was continued.
        let r = match resume(&dir, &log, Some(stop + 1)) {
            Err(RunError::Interrupted { .. }) => Ok(()),
            Ok(()) => panic!("the run did not stop at step {}", stop + 1),
            Err(e) => Err(e.to_string()),
        };
        if let Err(e) = &r {
            // The log is left as it was and no temporary file stays.
            assert!(std::fs::read(&log).unwrap() == bytes, "log changed: {e}");
            assert!(!dir.join("run.mcap.resume.tmp").exists());
        }
        r
    };
    let expect = |bytes: &[u8], words: &[&str]| {
        let e = attempt(bytes).unwrap_err();
        assert!(e.contains(log.to_str().unwrap()), "{e}");
        for w in words {
            assert!(e.contains(w), "{e:?} lacks {w:?}");
        }
    };
    // Cut before the checkpoint's frames: a hole.
    expect(
        &good[..good.len() / 3],
        &["cannot continue", "hole", "unfinished"],
    );
    // A chunk in the middle damaged.
    let mut flipped = good.clone();
    for b in &mut flipped[good.len() / 3..good.len() / 3 + 64] {
        *b ^= 0x5a;
    }
    expect(&flipped, &["cannot continue", "hole"]);
    expect(b"not an mcap file at all", &["not an MCAP file"]);
    expect(&[], &["not an MCAP file"]);
    expect(&good[..12], &["no sdem.run metadata"]);
    // The log of another run.
    let other = base.join("other");
    let mut s = scenario();
    s.seed += 1;
    let mut o = options(&other, 700, &other.join("other.mcap"));
    o.stop_after_step = Some(stop);
    assert!(run_scenario(&s, &o).is_err());
    expect(
        &std::fs::read(other.join("other.mcap")).unwrap(),
        &["not the log of this run", "seed"],
    );
    // Only the end magic lost (an unfinished file whose frames are all there): it goes on.
    attempt(&good[..good.len() - 8]).unwrap();
    let t = Trajectory::open(&log).unwrap();
    let c = Checkpoint::read(&dir.join("checkpoint.bin")).unwrap();
    assert_eq!(
        (c.step, t.frame_count() as u64),
        (stop + 1, c.runner.macro_rows)
    );
    // Random damage: an error or, when only what follows the checkpoint's frames was hit, a
    // log that goes on; never a panic.
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let (mut refused, mut continued) = (0, 0);
    for _ in 0..40 {
        let mut bytes = good.clone();
        match rng.random_range(0..3) {
            0 => bytes.truncate(rng.random_range(0..good.len())),
            1 => {
                for _ in 0..rng.random_range(1..8) {
                    let k = rng.random_range(0..bytes.len());
                    bytes[k] = rng.random();
                }
            }
            _ => {
                let k = rng.random_range(0..bytes.len());
                let n = rng.random_range(1..200).min(bytes.len() - k);
                bytes.drain(k..k + n);
            }
        }
        match attempt(&bytes) {
            Ok(()) => {
                continued += 1;
                let t = Trajectory::open(&log).unwrap();
                assert_eq!(t.summary_info("status"), Some("interrupted"));
                let c = Checkpoint::read(&dir.join("checkpoint.bin")).unwrap();
                assert_eq!(c.step, stop + 1);
                assert_eq!(t.frame_count() as u64, c.runner.macro_rows);
            }
            Err(e) => {
                refused += 1;
                assert!(e.contains(log.to_str().unwrap()), "{e}");
            }
        }
    }
    eprintln!("random damage: {refused} refused, {continued} continued");
    assert!(refused > 0);
    std::fs::remove_dir_all(&base).ok();
}
