//! Checkpoints and restart (`sdem run --checkpoint-every`, `sdem resume`): a resumed run is
//! bitwise the uninterrupted one, whatever the step it stopped at, however it died, and with
//! any thread count; damaged checkpoints are refused with a clear error.

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use sdem::run::checkpoint::{Checkpoint, CheckpointError, FORMAT_VERSION, RunnerState};
use sdem::run::{RunOptions, build_world, resume_run, run_scenario};
use sdem::scenario::Scenario;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

mod common;
use common::{SMALL_COMPACTION as SMALL, grain_bits};

fn scenario() -> Scenario {
    common::small_compaction()
}

fn temp_dir(name: &str) -> common::TempDir {
    common::temp_dir("ckpt", name)
}

fn options(out: &Path, every: u64) -> RunOptions {
    common::checkpointed(out, every)
}

/// Random kill moments: a generator seeded from the clock, so that every test run tries others.
fn clock_seeded_rng() -> ChaCha8Rng {
    ChaCha8Rng::seed_from_u64(
        std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .unwrap()
            .as_nanos() as u64,
    )
}

/// The final state of a finished run, from its last (complete) checkpoint.
fn final_state(dir: &Path) -> Checkpoint {
    let c = Checkpoint::read(&dir.join("checkpoint.bin")).unwrap();
    assert!(c.complete, "{}: the run did not finish", dir.display());
    c
}

/// Bitwise equality of two final states and of the files the runs wrote.
fn assert_same_run(reference: &Path, other: &Path) {
    let a = final_state(reference);
    let b = final_state(other);
    assert_eq!(a.step, b.step);
    assert_eq!(a.time.to_bits(), b.time.to_bits());
    assert_eq!(grain_bits(&a.grains), grain_bits(&b.grains));
    let walls = |c: &Checkpoint| -> Vec<[u64; 6]> {
        c.walls
            .iter()
            .map(|w| {
                [
                    w.point.x,
                    w.point.y,
                    w.normal.x,
                    w.normal.y,
                    w.velocity.x,
                    w.velocity.y,
                ]
                .map(f64::to_bits)
            })
            .collect()
    };
    assert_eq!(walls(&a), walls(&b));
    assert_eq!(a.program, b.program);
    assert_eq!(a.runner, b.runner);
    for file in ["macro.csv", "grains.csv"] {
        let x = std::fs::read(reference.join(file)).unwrap();
        let y = std::fs::read(other.join(file)).unwrap();
        assert!(x == y, "{file} differs between {reference:?} and {other:?}");
    }
}

#[test]
fn f64_round_trips_bit_exactly() {
    let specials = [
        0.0,
        -0.0,
        f64::MIN_POSITIVE,
        f64::MIN_POSITIVE / 3.0,
        -5e-324,
        5e-324,
        f64::MAX,
        -f64::MAX,
        0.1 + 0.2,
        1.0 / 3.0,
        std::f64::consts::PI,
        1e-300,
        1.234_567_891_234_567_8e208,
        f64::INFINITY,
        f64::NEG_INFINITY,
    ];
    // RON itself (used for the scenario inside a checkpoint) prints shortest round-trip floats.
    let text = ron::to_string(&specials.to_vec()).unwrap();
    let back: Vec<f64> = ron::from_str(&text).unwrap();
    assert_eq!(
        specials.map(f64::to_bits).to_vec(),
        back.iter().map(|x| x.to_bits()).collect::<Vec<_>>(),
        "{text}"
    );
    // The state is stored as bit patterns: NaN payloads survive too.
    let scenario = scenario();
    let world = build_world(&scenario).unwrap();
    let mut grains = world.grains().to_vec();
    let odd = [
        f64::from_bits(0x7ff8_dead_beef_0001),
        -0.0,
        5e-324,
        -f64::MAX,
    ];
    for (k, g) in grains.iter_mut().take(50).enumerate() {
        g.velocity.x = odd[k % 4];
        g.eps2_rate = specials[k % specials.len()];
        g.alpha = -odd[(k + 1) % 4];
    }
    let c = Checkpoint {
        scenario: scenario.clone(),
        complete: false,
        checkpoint_every: 7,
        checkpoint_seconds: None,
        step: 12,
        time: -0.0,
        grains: grains.clone(),
        walls: world.walls.clone(),
        totals: world.totals,
        kinetic: sdem::integration::KineticTotals {
            energy: -0.0,
            stress: [odd[0], 5e-324, -1.5],
        },
        program: sdem::boundary::loading::LoadingProgram::new(
            scenario.loading.clone(),
            &world.walls,
        ),
        runner: RunnerState {
            max_loaded_inertial_number: 5e-324,
            isotropic_curve: vec![(-0.0, f64::MIN_POSITIVE / 7.0)],
            last_good: grains.clone(),
            ..Default::default()
        },
        periodic: None,
        contact_history: sdem::integration::ContactHistory {
            pairs: vec![([0, 1], -0.0), ([0, 7], 5e-324), ([3, 4], -1.5)],
            walls: vec![(2, 3, f64::MIN_POSITIVE / 3.0)],
            dissipated: -0.0,
        },
    };
    let back = Checkpoint::from_bytes(&c.to_bytes(), "mem").unwrap();
    assert_eq!(grain_bits(&back.grains), grain_bits(&grains));
    assert_eq!(grain_bits(&back.runner.last_good), grain_bits(&grains));
    assert_eq!(back.time.to_bits(), (-0.0f64).to_bits());
    assert_eq!(back.kinetic.energy.to_bits(), (-0.0f64).to_bits());
    assert_eq!(
        back.kinetic.stress.map(f64::to_bits),
        c.kinetic.stress.map(f64::to_bits)
    );
    assert_eq!(
        back.runner.isotropic_curve[0].0.to_bits(),
        (-0.0f64).to_bits()
    );
    assert_eq!(back.runner.max_loaded_inertial_number.to_bits(), 1);
    assert_eq!(back.scenario, scenario);
    let history_bits = |h: &sdem::integration::ContactHistory| {
        let pairs: Vec<_> = h.pairs.iter().map(|(p, f)| (*p, f.to_bits())).collect();
        let walls: Vec<_> = h
            .walls
            .iter()
            .map(|(g, w, f)| (*g, *w, f.to_bits()))
            .collect();
        (pairs, walls, h.dissipated.to_bits())
    };
    assert_eq!(
        history_bits(&back.contact_history),
        history_bits(&c.contact_history)
    );
}

#[test]
fn resume_from_a_checkpoint_is_bitwise_the_uninterrupted_run() {
    let scenario = scenario();
    let reference = temp_dir("ref");
    let summary = run_scenario(&scenario, &options(&reference, 1_000_000_000)).unwrap();
    let total = summary.steps;
    assert!(total > 3000, "{total} steps");
    assert!(summary.jamming.is_some());
    // Stops at a row step, off a row step, just after the start, in the second phase.
    for stop in [1000, 1234, 1, total - 500] {
        let dir = temp_dir(&format!("stop{stop}"));
        let (c, path) = common::run_interrupted_at(&scenario, &options(&dir, 700), stop);
        assert_eq!(c.step, stop);
        assert!(!c.complete);
        resume_run(&c, &path, &options(&dir, 700)).unwrap();
        assert_same_run(&reference, &dir);
        // A finished run has nothing to resume.
        let done = Checkpoint::read(&path).unwrap();
        let err = resume_run(&done, &path, &options(&dir, 700)).unwrap_err();
        assert!(err.to_string().contains("nothing to resume"), "{err}");
        std::fs::remove_dir_all(&dir).ok();
    }
    // Resuming into another directory takes macro.csv from the checkpoint's.
    let dir = temp_dir("elsewhere-src");
    let mut opts = options(&dir, 500);
    opts.stop_after_step = Some(2500);
    assert!(run_scenario(&scenario, &opts).is_err());
    let other = temp_dir("elsewhere-dst");
    let path = dir.join("checkpoint.bin");
    resume_run(
        &Checkpoint::read(&path).unwrap(),
        &path,
        &options(&other, 500),
    )
    .unwrap();
    assert_same_run(&reference, &other);
    for d in [dir, other, reference] {
        std::fs::remove_dir_all(&d).ok();
    }
}

fn sdem() -> Command {
    Command::new(env!("CARGO_BIN_EXE_sdem"))
}

fn write_scenario(dir: &Path) -> PathBuf {
    let path = dir.join("small.ron");
    std::fs::write(&path, SMALL).unwrap();
    path
}

fn run_cli(args: &[&str]) {
    let out = sdem().args(args).output().unwrap();
    assert!(
        out.status.success(),
        "sdem {args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// Starts `sdem run` with checkpoints, waits for the first one and a little more, then stops it
/// with `stop` (SIGKILL or SIGTERM). Returns whether the run was cut before its end.
fn start_and_stop(
    scenario: &Path,
    dir: &Path,
    delay: Duration,
    stop: impl FnOnce(&mut std::process::Child),
) -> bool {
    start_and_stop_with(scenario, dir, &["--checkpoint-every", "300"], delay, stop)
}

/// [`start_and_stop`] with other checkpoint arguments.
fn start_and_stop_with(
    scenario: &Path,
    dir: &Path,
    checkpoint_args: &[&str],
    delay: Duration,
    stop: impl FnOnce(&mut std::process::Child),
) -> bool {
    let mut child = sdem()
        .args([
            "run",
            scenario.to_str().unwrap(),
            "--out",
            dir.to_str().unwrap(),
        ])
        .args(checkpoint_args)
        .args(["--threads", "2", "--quiet"])
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let started = Instant::now();
    while !dir.join("checkpoint.bin").exists() {
        assert!(started.elapsed() < Duration::from_secs(60), "no checkpoint");
        if child.try_wait().unwrap().is_some() {
            break;
        }
        std::thread::sleep(Duration::from_millis(2));
    }
    std::thread::sleep(delay);
    stop(&mut child);
    let output = child.wait_with_output().unwrap();
    let c = Checkpoint::read(&dir.join("checkpoint.bin")).unwrap();
    if c.complete {
        assert!(output.status.success());
    }
    !c.complete
}

#[test]
fn killed_run_resumes_bitwise_identical() {
    let base = temp_dir("kill");
    let scenario = write_scenario(&base);
    let reference = base.join("ref");
    run_cli(&[
        "run",
        scenario.to_str().unwrap(),
        "--out",
        reference.to_str().unwrap(),
        "--checkpoint-every",
        "300",
        "--threads",
        "2",
        "--quiet",
    ]);
    let mut rng = clock_seeded_rng();
    let mut cut = 0;
    for attempt in 0..4 {
        let dir = base.join(format!("run{attempt}"));
        let delay = Duration::from_millis(rng.random_range(0..250) >> attempt);
        // SIGKILL: no chance to clean up.
        let interrupted = start_and_stop(&scenario, &dir, delay, |c| c.kill().unwrap());
        if interrupted {
            cut += 1;
            let ckpt = dir.join("checkpoint.bin");
            let threads = if attempt % 2 == 0 { "1" } else { "2" };
            run_cli(&[
                "resume",
                ckpt.to_str().unwrap(),
                "--threads",
                threads,
                "--quiet",
            ]);
        }
        assert_same_run(&reference, &dir);
    }
    eprintln!("killed mid-run and resumed: {cut} of 4 runs");
    assert!(cut > 0, "every run finished before it could be killed");
    std::fs::remove_dir_all(&base).ok();
}

#[cfg(unix)]
#[test]
fn sigterm_writes_a_checkpoint_and_stops() {
    let base = temp_dir("term");
    let scenario = write_scenario(&base);
    let reference = base.join("ref");
    run_cli(&[
        "run",
        scenario.to_str().unwrap(),
        "--out",
        reference.to_str().unwrap(),
        "--checkpoint-every",
        "1000000",
        "--quiet",
    ]);
    let dir = base.join("run");
    let mut exit = None;
    let interrupted = start_and_stop(&scenario, &dir, Duration::from_millis(20), |c| {
        let status = Command::new("kill")
            .args(["-TERM", &c.id().to_string()])
            .status()
            .unwrap();
        assert!(status.success());
        exit = Some(());
    });
    assert!(exit.is_some());
    if interrupted {
        let c = Checkpoint::read(&dir.join("checkpoint.bin")).unwrap();
        eprintln!("SIGTERM: checkpoint at step {}", c.step);
        assert!(c.step > 0);
        run_cli(&[
            "resume",
            dir.join("checkpoint.bin").to_str().unwrap(),
            "--quiet",
        ]);
    }
    assert_same_run(&reference, &dir);
    std::fs::remove_dir_all(&base).ok();
}

#[test]
fn damaged_checkpoints_are_refused_with_a_clear_error() {
    let scenario = scenario();
    let dir = temp_dir("damaged");
    let mut opts = options(&dir, 100);
    opts.stop_after_step = Some(200);
    assert!(run_scenario(&scenario, &opts).is_err());
    let good = std::fs::read(dir.join("checkpoint.bin")).unwrap();
    let bad = dir.join("bad.bin");
    let check = |bytes: &[u8], expect: &str| {
        std::fs::write(&bad, bytes).unwrap();
        let err = Checkpoint::read(&bad).unwrap_err();
        let text = err.to_string();
        assert!(text.contains(expect), "{text}");
        assert!(text.contains("bad.bin"), "{text}");
        // The command line says the same, without a panic.
        let out = sdem()
            .args(["resume", bad.to_str().unwrap(), "--quiet"])
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success());
        assert!(stderr.starts_with("error: "), "{stderr}");
        assert!(stderr.contains(expect), "{stderr}");
        assert!(!stderr.contains("panicked"), "{stderr}");
        err
    };
    // Truncated: in the header, in the payload, one byte short.
    for n in [10, 30, good.len() / 2, good.len() - 1] {
        check(&good[..n], "truncated checkpoint");
    }
    check(&good[..3], "not an sdem checkpoint");
    // A flipped byte in the payload, and trailing bytes.
    let mut flipped = good.clone();
    let k = good.len() / 3;
    flipped[k] ^= 0x20;
    check(&flipped, "checksum mismatch");
    let mut longer = good.clone();
    longer.push(b'\n');
    check(&longer, "trailing bytes");
    // Another format version.
    let mut version = good.clone();
    version[8..12].copy_from_slice(&(FORMAT_VERSION + 1).to_le_bytes());
    match check(&version, "format version") {
        CheckpointError::Version {
            found, expected, ..
        } => assert_eq!((found, expected), (FORMAT_VERSION + 1, FORMAT_VERSION)),
        e => panic!("{e:?}"),
    }
    // Not a checkpoint at all.
    check(SMALL.as_bytes(), "not an sdem checkpoint");
    // A missing file.
    let out = sdem()
        .args(["resume", dir.join("none.bin").to_str().unwrap()])
        .output()
        .unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("cannot read the checkpoint"));
    // macro.csv shorter than the checkpoint says: refused, not silently continued.
    let path = dir.join("checkpoint.bin");
    let c = Checkpoint::read(&path).unwrap();
    std::fs::write(
        dir.join("macro.csv"),
        sdem::output::Measures::HEADER.to_string() + "\n",
    )
    .unwrap();
    let err = resume_run(&c, &path, &options(&dir, 100)).unwrap_err();
    assert!(err.to_string().contains("macro.csv"), "{err}");
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn one_and_two_threads_give_identical_outputs() {
    let scenario = scenario();
    let mut dirs = Vec::new();
    for threads in [1, 2] {
        let dir = temp_dir(&format!("threads{threads}"));
        common::with_threads(threads, || {
            run_scenario(&scenario, &options(&dir, 1_000_000_000))
        })
        .unwrap();
        dirs.push(dir);
    }
    assert_same_run(&dirs[0], &dirs[1]);
    for d in dirs {
        std::fs::remove_dir_all(&d).ok();
    }
}

fn mutate(rng: &mut ChaCha8Rng, input: &[u8]) -> Vec<u8> {
    let mut v = input.to_vec();
    for _ in 0..rng.random_range(1..4) {
        if v.is_empty() {
            break;
        }
        let k = rng.random_range(0..v.len());
        match rng.random_range(0..5) {
            0 => v[k] ^= 1 << rng.random_range(0..8),
            1 => v[k] = rng.random(),
            2 => v.truncate(k),
            3 => {
                v.remove(k);
            }
            _ => {
                let b = v[rng.random_range(0..v.len())];
                v.insert(k, b);
            }
        }
    }
    v
}

/// Random byte flips, replacements, truncations, deletions and duplications of a scenario file
/// and of a checkpoint (raw, and with a valid header over the mutated payload, so that the
/// decoder behind the checksum is reached): never a panic.
#[test]
fn fuzzed_scenarios_and_checkpoints_never_panic() {
    let mut rng = ChaCha8Rng::seed_from_u64(0x5dec_c4e7);
    let mut tried = 0;
    for _ in 0..3000 {
        let bytes = mutate(&mut rng, SMALL.as_bytes());
        let text = String::from_utf8_lossy(&bytes);
        if let Ok(s) = Scenario::parse(&text, "fuzz.ron") {
            let _ = s.validate();
        }
        tried += 1;
    }
    let scenario = scenario();
    let world = build_world(&scenario).unwrap();
    let mut small = scenario.clone();
    small.sample.count = Some(3);
    let c = Checkpoint {
        scenario: small.clone(),
        complete: false,
        checkpoint_every: 10,
        checkpoint_seconds: Some(0.25),
        step: 5,
        time: 0.25,
        grains: world.grains()[..3].to_vec(),
        walls: world.walls.clone(),
        totals: world.totals,
        kinetic: world.kinetic(),
        program: sdem::boundary::loading::LoadingProgram::new(small.loading.clone(), &world.walls),
        runner: RunnerState {
            confirmed_jamming: Some(sdem::run::Jamming {
                step: 3,
                phi: 0.5,
                z: 1.0,
                z_nr: 2.0,
                p_c: 1e-5,
            }),
            isotropic_curve: vec![(0.5, 1e-5)],
            last_good: world.grains()[..3].to_vec(),
            ..Default::default()
        },
        periodic: None,
        contact_history: Default::default(),
    };
    let good = c.to_bytes();
    assert_eq!(Checkpoint::from_bytes(&good, "mem").unwrap(), c);
    let header = 24;
    let mut decoded = 0;
    for i in 0..3000 {
        if i % 2 == 0 {
            let _ = Checkpoint::from_bytes(&mutate(&mut rng, &good), "fuzz");
        } else {
            let payload = mutate(&mut rng, &good[header..]);
            let mut bytes = good[..header].to_vec();
            bytes[12..20].copy_from_slice(&(payload.len() as u64).to_le_bytes());
            bytes[20..24].copy_from_slice(&sdem::run::checkpoint::crc32(&payload).to_le_bytes());
            bytes.extend_from_slice(&payload);
            if Checkpoint::from_bytes(&bytes, "fuzz").is_ok() {
                decoded += 1;
            }
        }
        tried += 1;
    }
    eprintln!("fuzz: {tried} inputs tried ({decoded} mutated checkpoints still decoded)");
    assert_eq!(tried, 6000);
}

/// Wall-clock checkpoints land on whatever step the clock says: a run killed at a random moment
/// resumes from such a checkpoint bitwise identical to an uninterrupted run without any.
#[test]
fn wall_clock_checkpoints_resume_bitwise() {
    let scenario = scenario();
    // Checkpoints every few milliseconds change nothing in the results.
    let reference = temp_dir("wall-ref");
    let quiet = run_scenario(&scenario, &options(&reference, 1_000_000_000)).unwrap();
    let timed = temp_dir("wall-timed");
    let mut opts = options(&timed, 0);
    opts.checkpoint_seconds = Some(0.005);
    let summary = run_scenario(&scenario, &opts).unwrap();
    eprintln!(
        "{} wall-clock checkpoints in {:.2} s",
        summary.checkpoints_written, summary.wall_seconds
    );
    assert!(summary.checkpoints_written > 2, "{summary:?}");
    assert_eq!(quiet.checkpoints_written, 1);
    assert_same_run(&reference, &timed);
    assert_eq!(final_state(&timed).checkpoint_seconds, Some(0.005));
    // Killed at a random moment after a wall-clock checkpoint, resumed with its interval.
    let base = temp_dir("wall-kill");
    let file = write_scenario(&base);
    let mut rng = clock_seeded_rng();
    let mut cut = 0;
    for attempt in 0..3 {
        let dir = base.join(format!("run{attempt}"));
        let delay = Duration::from_millis(rng.random_range(0..200) >> attempt);
        let interrupted = start_and_stop_with(
            &file,
            &dir,
            &["--checkpoint-every-seconds", "0.01"],
            delay,
            |c| c.kill().unwrap(),
        );
        if interrupted {
            cut += 1;
            let saved = Checkpoint::read(&dir.join("checkpoint.bin")).unwrap();
            assert_eq!(
                (saved.checkpoint_every, saved.checkpoint_seconds),
                (0, Some(0.01))
            );
            run_cli(&[
                "resume",
                dir.join("checkpoint.bin").to_str().unwrap(),
                "--quiet",
            ]);
        }
        assert_same_run(&reference, &dir);
    }
    eprintln!("killed mid-run and resumed: {cut} of 3 runs");
    assert!(cut > 0, "every run finished before it could be killed");
    for d in [reference, timed, base] {
        std::fs::remove_dir_all(&d).ok();
    }
}

/// `output.checkpoint` in the scenario turns checkpoints on; the command line overrides it.
#[test]
fn scenario_checkpoint_interval_and_its_override() {
    let base = temp_dir("scenario-interval");
    let path = base.join("small.ron");
    std::fs::write(
        &path,
        SMALL.replace(
            "output: (every: 50)",
            "output: (every: 50, checkpoint: EverySteps(400))",
        ),
    )
    .unwrap();
    let run = |dir: &str, extra: &[&str]| -> Checkpoint {
        let out = base.join(dir);
        let mut args = vec![
            "run",
            path.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ];
        args.extend_from_slice(extra);
        args.push("--quiet");
        run_cli(&args);
        final_state(&out)
    };
    let c = run("scenario", &[]);
    assert_eq!((c.checkpoint_every, c.checkpoint_seconds), (400, None));
    let c = run("steps", &["--checkpoint-every", "1000"]);
    assert_eq!((c.checkpoint_every, c.checkpoint_seconds), (1000, None));
    let c = run("seconds", &["--checkpoint-every-seconds", "600"]);
    assert_eq!((c.checkpoint_every, c.checkpoint_seconds), (0, Some(600.0)));
    assert_same_run(&base.join("scenario"), &base.join("seconds"));
    std::fs::remove_dir_all(&base).ok();
}

/// `sdem bench --from CHECKPOINT` times a run's own state. Expectation: the world it steps is
/// the checkpointed one (every grain bit, the walls, time and step), and the command times
/// that world rather than the dense packing, refusing the packing's options beside it.
#[test]
fn bench_from_a_checkpoint_steps_the_checkpointed_world() {
    let scenario = scenario();
    let dir = temp_dir("bench-from");
    let mut opts = options(&dir, 0);
    opts.stop_after_step = Some(300);
    assert!(
        run_scenario(&scenario, &opts).is_err(),
        "stopped runs end in an error"
    );
    let path = dir.join("checkpoint.bin");
    let saved = Checkpoint::read(&path).unwrap();
    assert_eq!(saved.step, 300);

    let world = sdem::run::world_from_checkpoint(&saved).unwrap();
    assert_eq!(world.step, saved.step);
    assert_eq!(world.time.to_bits(), saved.time.to_bits());
    assert_eq!(grain_bits(world.grains()), grain_bits(&saved.grains));
    let wall_points = |walls: &[sdem::boundary::walls::Wall]| -> Vec<[u64; 2]> {
        walls
            .iter()
            .map(|w| w.point.to_array().map(f64::to_bits))
            .collect()
    };
    assert_eq!(wall_points(&world.walls), wall_points(&saved.walls));

    let out = sdem()
        .args(["bench", "--steps", "3", "--threads", "1", "--from"])
        .arg(&path)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(stdout.contains("checkpoint:"), "{stdout}");
    let grains = format!("grains: {}", saved.grains.len());
    assert!(stdout.contains(&grains), "{stdout}");
    assert!(stdout.contains("grain-steps/s:"), "{stdout}");

    // The dense packing's options do not apply to a checkpoint's world.
    let out = sdem()
        .args(["bench", "--grains", "400", "--from"])
        .arg(&path)
        .output()
        .unwrap();
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("--grains") && stderr.contains("--from"),
        "{stderr}"
    );
    // A missing file is named.
    let missing = dir.join("no_such_checkpoint.bin");
    let out = sdem()
        .args(["bench", "--from"])
        .arg(&missing)
        .output()
        .unwrap();
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("no_such_checkpoint.bin"), "{stderr}");
}
