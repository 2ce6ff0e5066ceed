//! Checkpoints and restart of meshfree runs: a meshfree run stopped at any step and resumed
//! (through the library or `sdem resume`, with any thread count) writes the same `macro.csv`,
//! `grains.csv` and final checkpoint, byte for byte, as the uninterrupted run; damaged meshfree
//! checkpoints are refused with a clear error, and each solver's reader refuses the other's.

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use sdem::run::checkpoint::{
    AnyCheckpoint, Checkpoint, CheckpointError, FORMAT_VERSION, SDEM_FORMAT_VERSION,
};
use sdem::run::meshfree_checkpoint::MeshfreeCheckpoint;
use sdem::run::{RunError, RunOptions, resume_run, run_scenario};
use sdem::scenario::Scenario;
use std::path::{Path, PathBuf};
use std::process::Command;

mod common;
use common::with_threads;

/// The run stopped and resumed: [`common::MESHFREE_FOUR`].
use common::MESHFREE_FOUR as SCENARIO;

fn scenario() -> Scenario {
    common::meshfree_four()
}

fn temp_dir(name: &str) -> common::TempDir {
    common::temp_dir("mfckpt", name)
}

const EVERY: u64 = 4;

fn sdem() -> Command {
    Command::new(env!("CARGO_BIN_EXE_sdem"))
}

/// The uninterrupted run (on `threads` threads), with a checkpoint every [`EVERY`] steps.
fn reference(name: &str, threads: usize) -> common::TempDir {
    let dir = temp_dir(name);
    let summary = with_threads(threads, || {
        run_scenario(&scenario(), &common::checkpointed(&dir, EVERY))
    })
    .unwrap();
    assert_eq!(summary.steps, 16);
    dir
}

/// Runs the scenario on `threads` threads, stopped after step `stop`; the checkpoint's path.
fn interrupted(dir: &Path, stop: u64, threads: usize) -> PathBuf {
    let mut options = common::checkpointed(dir, EVERY);
    options.stop_after_step = Some(stop);
    match with_threads(threads, || run_scenario(&scenario(), &options)) {
        Err(RunError::Interrupted { step, .. }) => assert_eq!(step, stop),
        other => panic!("expected an interruption at {stop}, got {other:?}"),
    }
    dir.join("checkpoint.bin")
}

fn read(path: &Path) -> Vec<u8> {
    std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// The files of two finished runs are the same bytes.
fn assert_same_files(reference: &Path, other: &Path) {
    for file in ["macro.csv", "grains.csv", "checkpoint.bin"] {
        let (a, b) = (read(&reference.join(file)), read(&other.join(file)));
        assert!(
            a == b,
            "{file} differs between {} and {}",
            reference.display(),
            other.display()
        );
    }
}

#[test]
fn a_stopped_meshfree_run_resumes_bitwise_with_any_thread_count() {
    let reference = reference("ref", 2);
    let macro_csv = String::from_utf8(read(&reference.join("macro.csv"))).unwrap();
    assert!(
        macro_csv.lines().any(|l| l.contains(",servo,")),
        "{macro_csv}"
    );
    // Stopped inside the servo phase between two rows, at a row, and in the isotropic phase;
    // resumed on 1 or 2 threads after running on 2 or 1.
    for (stop, before, after) in [(11, 2, 1), (12, 1, 2), (5, 2, 2)] {
        let dir = temp_dir(&format!("stop{stop}"));
        let path = interrupted(&dir, stop, before);
        let c = MeshfreeCheckpoint::read(&path).unwrap();
        assert_eq!((c.step, c.complete), (stop, false));
        // The rows written after the checkpoint's are dropped on resume.
        let mut partial = read(&dir.join("macro.csv"));
        partial.extend_from_slice(b"99,garbage after the checkpoint");
        std::fs::write(dir.join("macro.csv"), partial).unwrap();
        let summary = with_threads(after, || {
            resume_run(&c, &path, &common::checkpointed(&dir, EVERY))
        })
        .unwrap();
        assert_eq!(summary.steps, 16);
        assert_same_files(&reference, &dir);
    }
    // The same through `sdem resume` (the solver read from the file), into another directory
    // (macro.csv copied there from the checkpoint's).
    let dir = temp_dir("cli");
    let path = interrupted(&dir, 9, 1);
    let resumed = temp_dir("cli-out");
    let out = sdem()
        .args([
            "resume",
            path.to_str().unwrap(),
            "--quiet",
            "--threads",
            "2",
        ])
        .args(["--out", resumed.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert_same_files(&reference, &resumed);
    // A finished run has nothing to resume.
    let done = AnyCheckpoint::read(&reference.join("checkpoint.bin")).unwrap();
    let err = resume_run(
        &done,
        &reference.join("checkpoint.bin"),
        &RunOptions::default(),
    )
    .unwrap_err();
    assert!(err.to_string().contains("nothing to resume"), "{err}");
}

/// Checks that `bytes` are refused by the reader and by `sdem resume` with a message holding
/// `expect`; returns the reader's error.
fn refused(dir: &Path, bytes: &[u8], expect: &str) -> RunError {
    let bad = dir.join("bad.bin");
    std::fs::write(&bad, bytes).unwrap();
    let err = match AnyCheckpoint::read(&bad) {
        Err(e) => RunError::Checkpoint(e),
        Ok(c) => resume_run(&c, &bad, &common::checkpointed(&dir.join("out"), 0))
            .expect_err("a damaged checkpoint was resumed"),
    };
    let text = err.to_string();
    assert!(text.contains(expect) && text.contains("bad.bin"), "{text}");
    let out = sdem()
        .args(["resume", bad.to_str().unwrap(), "--quiet"])
        .args(["--out", dir.join("cli").to_str().unwrap()])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    // (A checkpoint refused once its grains are rebuilt comes after the "resuming" line.)
    assert!(
        stderr
            .lines()
            .any(|l| l.starts_with("error: ") && l.contains(expect)),
        "{stderr}"
    );
    assert!(!stderr.contains("panicked"), "{stderr}");
    err
}

#[test]
fn damaged_meshfree_checkpoints_are_refused_with_a_clear_error() {
    let dir = temp_dir("damaged");
    let path = interrupted(&dir, 3, 2);
    let good = read(&path);
    assert_eq!(good[8..12], FORMAT_VERSION.to_le_bytes());
    for n in [30, good.len() / 2, good.len() - 1] {
        refused(&dir, &good[..n], "truncated checkpoint");
    }
    let mut flipped = good.clone();
    flipped[good.len() / 3] ^= 0x20;
    refused(&dir, &flipped, "checksum mismatch");
    let mut version = good.clone();
    version[8..12].copy_from_slice(&(FORMAT_VERSION + 1).to_le_bytes());
    match refused(&dir, &version, "format version") {
        RunError::Checkpoint(CheckpointError::Version {
            found, expected, ..
        }) => assert_eq!((found, expected), (FORMAT_VERSION + 1, FORMAT_VERSION)),
        e => panic!("{e:?}"),
    }
    // A meshfree payload under the SDEM version's header.
    let mut relabelled = good.clone();
    relabelled[8..12].copy_from_slice(&SDEM_FORMAT_VERSION.to_le_bytes());
    refused(&dir, &relabelled, "corrupt checkpoint");

    // Consistent files (right checksum) whose state does not fit the scenario's grains.
    let c = MeshfreeCheckpoint::read(&path).unwrap();
    let mut short = c.clone();
    short.state.v.pop();
    refused(&dir, &short.to_bytes(), "displacements, ");
    let mut fewer = c.clone();
    for s in [&mut fewer.state, &mut fewer.last_good.1] {
        s.u.truncate(10);
        s.v.truncate(10);
        s.a.truncate(10);
    }
    refused(&dir, &fewer.to_bytes(), "10 displacements for the");
    let mut stranger = c.clone();
    assert!(
        !stranger.last.elements.is_empty(),
        "no contacts at the checkpoint"
    );
    stranger.last.elements[0].key.slave = 99;
    refused(&dir, &stranger.to_bytes(), "for 4 grains and 4 walls");
    let mut off_grid = c.clone();
    off_grid.last.elements[0].dofs[0] = 1 << 40;
    refused(&dir, &off_grid.to_bytes(), "contact element on DoF");

    // Each solver's reader refuses the other's checkpoints.
    let err = Checkpoint::read(&path).unwrap_err();
    assert!(
        matches!(err, CheckpointError::OtherSolver { .. }),
        "{err:?}"
    );
    assert!(
        err.to_string()
            .contains("a checkpoint of a run with the meshfree solver, not the SDEM"),
        "{err}"
    );
    let sdem_dir = temp_dir("sdem");
    let mut options = common::checkpointed(&sdem_dir, 10);
    options.stop_after_step = Some(20);
    assert!(run_scenario(&common::small_compaction(), &options).is_err());
    let sdem_file = read(&sdem_dir.join("checkpoint.bin"));
    assert_eq!(sdem_file[8..12], SDEM_FORMAT_VERSION.to_le_bytes());
    let err = MeshfreeCheckpoint::from_bytes(&sdem_file, "sdem.bin").unwrap_err();
    assert!(
        err.to_string()
            .contains("with the SDEM solver, not the meshfree solver"),
        "{err}"
    );
    assert!(matches!(
        AnyCheckpoint::from_bytes(&sdem_file, "sdem.bin"),
        Ok(AnyCheckpoint::Sdem(_))
    ));

    // Random damage behind a valid header never panics; what still decodes re-encodes.
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let header = 24;
    let mut decoded = 0;
    for _ in 0..300 {
        let mut payload = good[header..].to_vec();
        for _ in 0..rng.random_range(1..4) {
            let k = rng.random_range(0..payload.len());
            match rng.random_range(0..3) {
                0 => payload[k] = rng.random(),
                1 => {
                    payload.remove(k);
                }
                _ => payload.insert(k, b"0123456789(),:[]-"[rng.random_range(0..17)]),
            }
        }
        let mut bytes = good[..header].to_vec();
        bytes[12..20].copy_from_slice(&(payload.len() as u64).to_le_bytes());
        bytes[20..24].copy_from_slice(&sdem::run::checkpoint::crc32(&payload).to_le_bytes());
        bytes.extend_from_slice(&payload);
        if let Ok(c) = MeshfreeCheckpoint::from_bytes(&bytes, "fuzz") {
            decoded += 1;
            let again = c.to_bytes();
            assert!(MeshfreeCheckpoint::from_bytes(&again, "fuzz").is_ok());
        }
    }
    eprintln!("fuzz: 300 damaged payloads, {decoded} still decoded");
}

/// Runs [`SCENARIO`] with its sample line replaced by `sample` (which reads `file`, written
/// with `content` into a fresh folder) and the other replacements `edits`, uninterrupted and
/// stopped at step 5; deletes the file, resumes the stopped run and checks it against the
/// uninterrupted one byte for byte.
fn resumes_bitwise_without_its_file(
    name: &str,
    file: &str,
    content: &str,
    sample: &str,
    edits: &[(&str, &str)],
) {
    let base = temp_dir(name);
    std::fs::write(base.join(file), content).unwrap();
    let mut text = SCENARIO
        .replace(
            "count: 4, box_width: 0.34, box_height: 0.34,\n             radii: Uniform(min: 0.06, max: 0.07)",
            sample,
        )
        .replace("max_steps: 16", "max_steps: 8");
    for (from, to) in edits {
        text = text.replace(from, to);
    }
    assert!(text.contains(file));
    std::fs::write(base.join("s.ron"), text).unwrap();
    let (scenario, _) = Scenario::load(&base.join("s.ron")).unwrap();
    let reference = base.join("ref");
    run_scenario(&scenario, &common::checkpointed(&reference, EVERY)).unwrap();
    let dir = base.join("stopped");
    let mut options = common::checkpointed(&dir, EVERY);
    options.stop_after_step = Some(5);
    assert!(matches!(
        run_scenario(&scenario, &options),
        Err(RunError::Interrupted { step: 5, .. })
    ));
    std::fs::remove_file(base.join(file)).unwrap();
    let path = dir.join("checkpoint.bin");
    let c = AnyCheckpoint::read(&path).unwrap();
    resume_run(&c, &path, &common::checkpointed(&dir, EVERY)).unwrap();
    assert_same_files(&reference, &dir);
}

/// A scenario that reads its discs from a sample file: the checkpoint holds them, and the run
/// resumes bitwise after the file is gone.
#[test]
fn a_meshfree_run_from_a_sample_file_resumes_bitwise_without_the_file() {
    resumes_bitwise_without_its_file(
        "file",
        "discs.csv",
        "0.09,0.09,0.07\n0.25,0.1,0.065\n0.17,0.25,0.06\n",
        "box_width: 0.34, box_height: 0.34, file: \"discs.csv\"",
        &[],
    );
}

/// A scenario that reads its grains' contours from a shape file: the checkpoint holds them,
/// and the run resumes bitwise after the file is gone.
#[test]
fn a_meshfree_run_from_a_shape_file_resumes_bitwise_without_the_file() {
    resumes_bitwise_without_its_file(
        "shapes",
        "grains.shapes",
        // Three squares of side 0.12, apart from each other and from the walls.
        "grain a\n0.04 0.04\n0.16 0.04\n0.16 0.16\n0.04 0.16\n\
         grain b\n0.19 0.04\n0.31 0.04\n0.31 0.16\n0.19 0.16\n\
         grain c\n0.1 0.19\n0.22 0.19\n0.22 0.31\n0.1 0.31\n",
        "box_width: 0.34, box_height: 0.34, shapes: File(\"grains.shapes\")",
        // A square's interior takes fewer nodes than a disc's: 24 on the contour are enough.
        &[("boundary_nodes: 16", "boundary_nodes: 24")],
    );
}
