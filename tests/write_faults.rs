//! Faults on the write side, with the real `sdem` binary:
//!
//! - a full disk while writing the checkpoint, `macro.csv` or the MCAP log, made real with a
//!   file size limit (`RLIMIT_FSIZE`, as `ulimit -f` sets it, with `SIGXFSZ` ignored so that
//!   the write fails with `EFBIG` as on a full disk, unprivileged): the run stops with an error
//!   naming the file, the checkpoint written before is intact, and `sdem resume` from it ends
//!   bitwise identical to the uninterrupted run;
//! - two runs with the same `--out`: the second refuses, naming the directory and the first
//!   run's process; a killed run's lock does not block the next one;
//! - an output directory that cannot be written: an error before the run starts.
#![cfg(all(target_os = "linux", target_pointer_width = "64"))]

mod common;

use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};

/// ~1500 steps of 40 grains: an isotropic compaction through jamming, then a relaxation; a
/// `macro.csv` row every 20 steps. Well under a second in release.
const SCENARIO: &str = r#"
Scenario(
    name: "write_faults",
    seed: 7,
    sample: (count: 40, box_width: 0.3, box_height: 0.3,
             radii: Gaussian(mean: 0.012, std_dev: 0.0024, min: 0.008, max: 0.016)),
    material: (young: 1.0, poisson: 0.5, density: 1.0),
    loading: [
        Isotropic(rate: Constant(5e-2), until: PackingFraction(0.84)),
        Relax(until: Steps(400)),
    ],
    output: (every: 20),
)
"#;

const EVERY: &str = "100";

fn sdem() -> Command {
    Command::new(env!("CARGO_BIN_EXE_sdem"))
}

fn run(cmd: &mut Command) -> Output {
    cmd.stdin(Stdio::null()).output().expect("starting sdem")
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// A fresh folder with the scenario in it.
fn setup(name: &str) -> (common::TempDir, PathBuf) {
    setup_with(name, SCENARIO)
}

/// A fresh folder with the scenario `text` in it.
fn setup_with(name: &str, text: &str) -> (common::TempDir, PathBuf) {
    let dir = common::temp_dir("write-faults", name);
    let scenario = dir.join("s.ron");
    std::fs::write(&scenario, text).unwrap();
    (dir, scenario)
}

/// `sdem run` of the scenario into `out` with a checkpoint every [`EVERY`] steps (and an MCAP
/// log when asked), under a file size limit of `limit` bytes when given.
fn run_into(scenario: &Path, out: &Path, mcap: Option<&Path>, limit: Option<u64>) -> Output {
    let mut cmd = sdem();
    cmd.arg("run").arg(scenario).arg("--out").arg(out).args([
        "--quiet",
        "--threads",
        "1",
        "--checkpoint-every",
        EVERY,
    ]);
    if let Some(m) = mcap {
        cmd.arg("--mcap").arg(m);
    }
    if let Some(bytes) = limit {
        file_size_limit(&mut cmd, bytes);
    }
    run(&mut cmd)
}

/// The child's largest file: `bytes` (`setrlimit(RLIMIT_FSIZE)`, what `ulimit -f` sets), with
/// `SIGXFSZ` ignored so that a write beyond it fails with `EFBIG` like a write to a full disk
/// instead of killing the process.
fn file_size_limit(cmd: &mut Command, bytes: u64) {
    use std::os::unix::process::CommandExt;
    unsafe extern "C" {
        fn setrlimit(resource: i32, limit: *const [u64; 2]) -> i32;
        fn signal(signum: i32, handler: usize) -> usize;
    }
    const RLIMIT_FSIZE: i32 = 1;
    const SIGXFSZ: i32 = 25;
    const SIG_IGN: usize = 1;
    // SAFETY: between fork and exec the closure calls only the async-signal-safe `signal` and
    // `setrlimit`, on its own copies of plain integers.
    unsafe {
        cmd.pre_exec(move || {
            signal(SIGXFSZ, SIG_IGN);
            let limit = [bytes, bytes];
            if setrlimit(RLIMIT_FSIZE, &limit) != 0 {
                return Err(std::io::Error::last_os_error());
            }
            Ok(())
        });
    }
}

fn size(path: &Path) -> u64 {
    std::fs::metadata(path)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        .len()
}

/// The run under the limit failed, naming `file` in its message, and left an intact checkpoint
/// from before the end; `sdem resume` from it (without the limit) ends with the reference
/// run's `macro.csv`, `grains.csv` and final checkpoint, byte for byte.
fn assert_failed_then_resumes(
    failed: &Output,
    out: &Path,
    reference: &Path,
    file: &Path,
    mcap: Option<&Path>,
) -> u64 {
    let message = stderr(failed);
    assert!(!failed.status.success(), "the run did not fail:\n{message}");
    assert!(
        message.contains(&file.display().to_string()) && message.contains("File too large"),
        "the error does not name {}:\n{message}",
        file.display()
    );
    assert!(!message.contains("panicked"), "{message}");
    let checkpoint = out.join("checkpoint.bin");
    assert!(
        !out.join("checkpoint.bin.tmp").exists(),
        "a partial checkpoint.bin.tmp is left"
    );
    let saved = sdem::run::checkpoint::Checkpoint::read(&checkpoint)
        .expect("the checkpoint from before the failure is intact");
    let last = sdem::run::checkpoint::Checkpoint::read(&reference.join("checkpoint.bin")).unwrap();
    assert!(
        !saved.complete && saved.step > 0 && saved.step < last.step,
        "checkpoint at step {} of {}",
        saved.step,
        last.step
    );
    let mut cmd = sdem();
    cmd.arg("resume")
        .arg(&checkpoint)
        .args(["--quiet", "--threads", "1"]);
    if let Some(m) = mcap {
        cmd.arg("--mcap").arg(m);
    }
    let resumed = run(&mut cmd);
    assert!(resumed.status.success(), "{}", stderr(&resumed));
    for name in ["macro.csv", "grains.csv", "checkpoint.bin"] {
        assert!(
            std::fs::read(out.join(name)).unwrap() == std::fs::read(reference.join(name)).unwrap(),
            "{name} of the resumed run differs from the uninterrupted run's"
        );
    }
    saved.step
}

/// A full disk while writing a checkpoint: the limit lies just under the final checkpoint's
/// size (a checkpoint grows with the isotropic curve it keeps), above everything else the run
/// writes (`macro.csv` has a row every 400 steps here).
#[test]
fn full_disk_while_writing_a_checkpoint() {
    let (dir, scenario) = setup_with("checkpoint", &SCENARIO.replace("every: 20", "every: 400"));
    let reference = dir.join("reference");
    let done = run_into(&scenario, &reference, None, None);
    assert!(done.status.success(), "{}", stderr(&done));
    let limit = size(&reference.join("checkpoint.bin")) - 1;
    for other in ["macro.csv", "grains.csv", "summary.txt"] {
        assert!(
            size(&reference.join(other)) < limit,
            "{other} is larger than the checkpoint: the test needs the checkpoint to be the first file to reach the limit"
        );
    }
    let out = dir.join("limited");
    let failed = run_into(&scenario, &out, None, Some(limit));
    assert!(
        stderr(&failed).contains("writing the checkpoint"),
        "{}",
        stderr(&failed)
    );
    let step =
        assert_failed_then_resumes(&failed, &out, &reference, &out.join("checkpoint.bin"), None);
    eprintln!("checkpoint write failed; resumed from step {step}");
    std::fs::remove_dir_all(&dir).ok();
}

/// A full disk while appending to `macro.csv`: the limit is half its final size, above every
/// checkpoint's.
#[test]
fn full_disk_while_writing_macro_csv() {
    let (dir, scenario) = setup("macro");
    let reference = dir.join("reference");
    let done = run_into(&scenario, &reference, None, None);
    assert!(done.status.success(), "{}", stderr(&done));
    let limit = size(&reference.join("macro.csv")) / 2;
    assert!(
        size(&reference.join("checkpoint.bin")) < limit,
        "the checkpoint is larger than half of macro.csv: the test needs macro.csv to reach the limit first"
    );
    let out = dir.join("limited");
    let failed = run_into(&scenario, &out, None, Some(limit));
    let step = assert_failed_then_resumes(&failed, &out, &reference, &out.join("macro.csv"), None);
    eprintln!("macro.csv write failed; resumed from step {step}");
    std::fs::remove_dir_all(&dir).ok();
}

/// A full disk while writing the MCAP log: the limit is half its final size; `sdem resume
/// --mcap` continues the cut log into the uninterrupted run's, message for message.
#[test]
fn full_disk_while_writing_the_mcap_log() {
    let (dir, scenario) = setup("mcap");
    let reference = dir.join("reference");
    let reference_log = dir.join("reference.mcap");
    let done = run_into(&scenario, &reference, Some(&reference_log), None);
    assert!(done.status.success(), "{}", stderr(&done));
    let limit = size(&reference_log) / 2;
    for other in ["macro.csv", "checkpoint.bin"] {
        assert!(
            size(&reference.join(other)) < limit,
            "{other} is larger than half the log: the test needs the log to reach the limit first"
        );
    }
    let out = dir.join("limited");
    let log = dir.join("limited.mcap");
    let failed = run_into(&scenario, &out, Some(&log), Some(limit));
    let step = assert_failed_then_resumes(&failed, &out, &reference, &log, Some(&log));
    common::mcap::assert_same_log(&reference_log, &log, 10);
    eprintln!("MCAP write failed; resumed from step {step}");
    std::fs::remove_dir_all(&dir).ok();
}

/// A second run with the same `--out` refuses while the first holds the directory, naming both;
/// once the first is killed, its lock file does not block a new run.
#[test]
fn a_second_run_on_the_same_output_directory_refuses() {
    let (dir, scenario) = setup("lock");
    let out = dir.join("out");
    // The first run: long enough to be still running while the second starts.
    let long = dir.join("long.ron");
    std::fs::write(
        &long,
        SCENARIO.replace("Relax(until: Steps(400))", "Relax(until: Steps(100000000))"),
    )
    .unwrap();
    let mut first = sdem()
        .arg("run")
        .arg(&long)
        .arg("--out")
        .arg(&out)
        .args(["--quiet", "--threads", "1"])
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let lock = out.join(sdem::output::lock::LOCK_FILE);
    let pid = first.id().to_string();
    let started = std::time::Instant::now();
    while std::fs::read_to_string(&lock)
        .ok()
        .as_deref()
        .map(str::trim)
        != Some(pid.as_str())
    {
        assert!(
            started.elapsed().as_secs() < 60,
            "the first run never took the lock"
        );
        assert!(first.try_wait().unwrap().is_none(), "the first run ended");
        std::thread::sleep(std::time::Duration::from_millis(10));
    }
    let second = run(sdem()
        .arg("run")
        .arg(&scenario)
        .arg("--out")
        .arg(&out)
        .arg("--quiet"));
    let message = stderr(&second);
    first.kill().unwrap();
    first.wait().unwrap();
    assert!(!second.status.success(), "the second run did not refuse");
    assert!(
        message.contains(&format!("{} is in use by another sdem run", out.display()))
            && message.contains(&format!("process {pid}")),
        "{message}"
    );
    // The killed run left its lock file; the operating system released its lock.
    assert!(lock.exists());
    let third = run(sdem()
        .arg("run")
        .arg(&scenario)
        .arg("--out")
        .arg(&out)
        .arg("--quiet"));
    assert!(third.status.success(), "{}", stderr(&third));
    std::fs::remove_dir_all(&dir).ok();
}

/// An output directory that cannot be created or written: a clear error before the run starts.
#[test]
fn an_unwritable_output_directory_is_an_error_before_the_run() {
    use std::os::unix::fs::PermissionsExt;
    let (dir, scenario) = setup("unwritable");
    // Under a regular file: no one can create it, root included.
    let file = dir.join("a_file");
    std::fs::write(&file, "").unwrap();
    let out = file.join("out");
    let o = run(sdem().arg("run").arg(&scenario).arg("--out").arg(&out));
    let message = stderr(&o);
    assert!(!o.status.success());
    assert!(
        message.contains(&format!(
            "cannot write in the output directory {} (creating it): Not a directory",
            out.display()
        )),
        "{message}"
    );
    assert!(
        !message.contains("grains, dt ="),
        "the run started:\n{message}"
    );
    // Read-only (permission bits do not stop root: then only the check above applies).
    let ro = dir.join("read_only");
    std::fs::create_dir(&ro).unwrap();
    std::fs::set_permissions(&ro, std::fs::Permissions::from_mode(0o555)).unwrap();
    let probe = ro.join("probe");
    if std::fs::write(&probe, "").is_ok() {
        eprintln!("running as root: the read-only case is not checked");
    } else {
        let o = run(sdem().arg("run").arg(&scenario).arg("--out").arg(&ro));
        let message = stderr(&o);
        assert!(!o.status.success());
        assert!(
            message.contains(&format!(
                "cannot write in the output directory {} (creating its lock file): \
                 Permission denied",
                ro.display()
            )),
            "{message}"
        );
        assert!(
            !message.contains("grains, dt ="),
            "the run started:\n{message}"
        );
        assert!(!ro.join("macro.csv").exists());
    }
    std::fs::set_permissions(&ro, std::fs::Permissions::from_mode(0o755)).unwrap();
    std::fs::remove_dir_all(&dir).ok();
}
