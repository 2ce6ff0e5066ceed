//! Trajectory logs of meshfree runs: `sdem run --mcap` writes each grain's boundary-node
//! contour (`/contours`) with its mean stress; the log reads back equal to `grains.csv`, and
//! `sdem render` / `sdem inspect` read it. `sdem resume --mcap` continues the log of a stopped
//! or killed meshfree run to exactly the uninterrupted run's, and starts a new one holding the
//! continued part when the file does not exist.

use sdem::boundary::walls::{BOTTOM, LEFT, RIGHT, TOP};
use sdem::output::mcap::McapSettings;
use sdem::output::mcap::{
    TOPIC_CONTOURS, TOPIC_GRAINS, TOPIC_MACRO, TOPIC_SCENE, TOPIC_WALLS, Trajectory, scan_log,
};
use sdem::run::meshfree::Meshfree;
use sdem::run::meshfree_checkpoint::MeshfreeCheckpoint;
use sdem::run::{RunError, RunOptions, resume_run, run_scenario};
use sdem::scenario::Scenario;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;

mod common;

/// Four discs squeezed by the walls for six steps (about a second); a frame every 3 steps and
/// at jamming. Two grains touch a wall by the end: their mean stress is not zero.
const FOUR_DISCS: &str = r#"
Scenario(
    name: "mf_four",
    seed: 5,
    sample: (count: 4, box_width: 0.34, box_height: 0.34,
             radii: Uniform(min: 0.06, max: 0.065)),
    material: (young: 1.0, poisson: 0.3, density: 1.0),
    model: Meshfree((boundary_nodes: 16, rayleigh_alpha: 5.0)),
    time_step: Fixed(0.01),
    loading: [ Isotropic(rate: Constant(2.0), until: PackingFraction(0.88)) ],
    output: (every: 3, max_steps: 6),
)
"#;

fn sdem() -> Command {
    Command::new(env!("CARGO_BIN_EXE_sdem"))
}

/// The run of [`FOUR_DISCS`] with `--mcap` (once per test binary): its folder and log.
fn run() -> &'static (PathBuf, PathBuf) {
    static RUN: OnceLock<(PathBuf, PathBuf)> = OnceLock::new();
    RUN.get_or_init(|| {
        let dir = std::env::temp_dir().join(format!("sdem-mfmcap-{}", std::process::id()));
        std::fs::remove_dir_all(&dir).ok();
        std::fs::create_dir_all(&dir).unwrap();
        let scenario = dir.join("four.ron");
        std::fs::write(&scenario, FOUR_DISCS).unwrap();
        let out = dir.join("out");
        let log = dir.join("four.mcap");
        let o = sdem()
            .arg("run")
            .arg(&scenario)
            .arg("--out")
            .arg(&out)
            .arg("--mcap")
            .arg(&log)
            .arg("--quiet")
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        (out, log)
    })
}

/// The rows of a CSV file after its header, split at commas.
fn csv_rows(path: &Path) -> Vec<Vec<String>> {
    std::fs::read_to_string(path)
        .unwrap()
        .lines()
        .skip(1)
        .map(|l| l.split(',').map(str::to_string).collect())
        .collect()
}

fn close(a: f64, b: f64, tol: f64) -> bool {
    (a - b).abs() <= tol
}

#[test]
fn a_meshfree_log_reads_back_equal_to_grains_csv() {
    let (out, path) = run();
    let log = Trajectory::open(path).unwrap();
    assert_eq!(log.solver(), "meshfree");
    assert_eq!(log.run_info("solver"), Some("meshfree"));
    let topics: Vec<&str> = log.channels().iter().map(|c| c.topic.as_str()).collect();
    assert_eq!(
        topics,
        [TOPIC_CONTOURS, TOPIC_WALLS, TOPIC_MACRO, TOPIC_SCENE]
    );
    assert!(log.channel(TOPIC_GRAINS).is_none());

    // One frame per macro.csv row, each with its row.
    let rows = csv_rows(&out.join("macro.csv"));
    assert!(rows.len() >= 2, "{rows:?}");
    assert_eq!(log.frame_count(), rows.len());
    assert_eq!(log.macro_rows().unwrap().len(), rows.len());
    for (k, row) in rows.iter().enumerate() {
        let frame = log.frame(k as i64).unwrap();
        assert_eq!(frame.step.to_string(), row[0], "frame {k}");
        let m = frame.measures.as_ref().unwrap();
        assert_eq!(m.step, frame.step);
        assert!(close(m.p_c, row[6].parse().unwrap(), 1e-9), "frame {k}");
        assert!(frame.grains.is_empty() && frame.contacts.is_empty());
    }

    // The last frame against grains.csv (the state at the end of the run) and the solver's
    // node counts.
    let scenario = Scenario::parse(FOUR_DISCS, "four.ron").unwrap();
    let sim = Meshfree::new(&scenario).unwrap();
    let grains = csv_rows(&out.join("grains.csv"));
    let frame = log.frame(-1).unwrap();
    assert_eq!(frame.step.to_string(), rows.last().unwrap()[0]);
    let contours = frame
        .contours
        .as_ref()
        .expect("a meshfree frame has contours");
    assert_eq!(contours.len(), grains.len());
    assert_eq!(frame.grain_count(), 4);
    let mut loaded = 0;
    for (g, (c, row)) in contours.iter().zip(&grains).enumerate() {
        let value = |k: usize| row[k].parse::<f64>().unwrap();
        assert_eq!(c.grain as usize, g);
        assert_eq!(row[0], g.to_string());
        assert_eq!(c.points.len(), sim.assembly.grains[g].nodes.boundary_count);
        let (area, centroid) = c.area_centroid();
        assert!(
            close(centroid.x, value(1), 1e-9),
            "grain {g}: {centroid} vs {row:?}"
        );
        assert!(
            close(centroid.y, value(2), 1e-9),
            "grain {g}: {centroid} vs {row:?}"
        );
        assert!(close(area, value(3), 1e-9 * value(3)), "grain {g}: {area}");
        for k in 0..3 {
            assert!(
                close(c.stress[k], value(4 + k), 1e-9),
                "grain {g}: {:?}",
                c.stress
            );
        }
        assert!(close(c.mean_stress_c, value(7), 1e-9), "grain {g}");
        assert_eq!(c.mean_stress_c, -0.5 * (c.stress[0] + c.stress[1]));
        if c.mean_stress_c > 1e-3 {
            loaded += 1;
        }
        // Deformed, not the reference disc: the points moved with the grain.
        assert!(c.points.iter().all(|p| p.is_finite()));
    }
    assert!(
        loaded >= 1,
        "no loaded grain: the stress check would be vacuous"
    );
    // The contours moved between the first frame and the last.
    let first = log.frame(0).unwrap();
    assert_ne!(first.contours, frame.contours);

    // The walls are those of the box of the macro row.
    let m = frame.measures.as_ref().unwrap();
    assert_eq!(frame.walls.len(), 4);
    let w = &frame.walls;
    assert!(close(
        w[RIGHT].point.x - w[LEFT].point.x,
        m.box_width,
        1e-12
    ));
    assert!(close(
        w[TOP].point.y - w[BOTTOM].point.y,
        m.box_height,
        1e-12
    ));
}

#[test]
fn the_scene_of_a_meshfree_log_draws_filled_contours() {
    let (_, path) = run();
    let mut messages: Vec<(u16, Vec<u8>)> = Vec::new();
    let scan = scan_log(path, |header, data| {
        messages.push((header.channel_id, data.to_vec()));
        Ok(true)
    })
    .unwrap();
    let scene = scan
        .channels
        .iter()
        .find(|(_, c)| c.topic == TOPIC_SCENE)
        .map(|(id, _)| *id)
        .unwrap();
    let scenes: Vec<String> = messages
        .into_iter()
        .filter(|(id, _)| *id == scene)
        .map(|(_, data)| String::from_utf8(data).unwrap())
        .collect();
    let log = Trajectory::open(path).unwrap();
    assert_eq!(scenes.len(), log.frame_count());
    let frame = log.frame(-1).unwrap();
    let last = scenes.last().unwrap();
    // One fan and one outline per grain, and the box.
    for c in frame.contours.as_ref().unwrap() {
        let n = c.points.len();
        let fan: Vec<String> = (0..n)
            .map(|i| format!("0,{},{}", i + 1, (i + 1) % n + 1))
            .collect();
        let indices = format!("\"indices\":[{}]", fan.join(","));
        assert_eq!(last.matches(&indices).count(), 4, "{indices}");
    }
    assert_eq!(last.matches("{\"type\":1,").count(), 5);
    assert!(last.contains("\"id\":\"box\""));
    // Valid JSON, where a Python is at hand to say so.
    if let Ok(mut child) = Command::new("python3")
        .args(["-c", "import json, sys; json.load(sys.stdin)"])
        .stdin(std::process::Stdio::piped())
        .spawn()
    {
        use std::io::Write;
        child
            .stdin
            .take()
            .unwrap()
            .write_all(last.as_bytes())
            .unwrap();
        assert!(child.wait().unwrap().success(), "{last}");
    }
}

#[test]
fn render_and_inspect_read_a_meshfree_log() {
    let (out, path) = run();
    let png = out.join("last.png");
    let o = sdem()
        .arg("render")
        .arg(path)
        .arg("--out")
        .arg(&png)
        .args(["--size", "400"])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{stderr}");
    assert!(stderr.contains("4 grains"), "{stderr}");
    // The picture: the box 400 px along its longer side, margins, caption and colour bar.
    let log = Trajectory::open(path).unwrap();
    let w = log.frame(-1).unwrap().walls;
    let (bw, bh) = (
        w[RIGHT].point.x - w[LEFT].point.x,
        w[TOP].point.y - w[BOTTOM].point.y,
    );
    let scale = 400.0 / bw.max(bh);
    let width = 16 + (bw * scale).round() as u32 + 16 + 170;
    let height = 64 + (bh * scale).round() as u32 + 16;
    let bytes = std::fs::read(&png).unwrap();
    assert!(bytes.len() > 1000);
    assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n");
    assert_eq!(&bytes[12..16], b"IHDR");
    let be = |k: usize| u32::from_be_bytes(bytes[k..k + 4].try_into().unwrap());
    assert_eq!((be(16), be(20)), (width, height));
    assert!(stderr.contains(&format!("{width}x{height} px")), "{stderr}");

    let o = sdem().arg("inspect").arg(path).output().unwrap();
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(
        stdout.contains(&format!("frames: {}\n", log.frame_count())),
        "{stdout}"
    );
    assert!(stdout.contains("meshfree trajectory"), "{stdout}");
    assert!(stdout.contains(TOPIC_CONTOURS), "{stdout}");
}

/// A checkpoint every this many steps in the stopped and resumed runs.
const EVERY: u64 = 4;

fn options(out: &Path, log: &Path) -> RunOptions {
    RunOptions {
        mcap: Some(McapSettings::new(log)),
        ..common::checkpointed(out, EVERY)
    }
}

/// The log of the uninterrupted run of [`common::MESHFREE_FOUR`] (once per test binary).
fn reference() -> &'static PathBuf {
    static LOG: OnceLock<PathBuf> = OnceLock::new();
    LOG.get_or_init(|| {
        let dir = common::temp_dir("mfmcap", "ref").keep();
        let log = dir.join("ref.mcap");
        let summary = run_scenario(&common::meshfree_four(), &options(&dir, &log)).unwrap();
        assert_eq!(summary.steps, 16);
        log
    })
}

/// Runs [`common::MESHFREE_FOUR`] into `dir` with `--mcap log`, stopped after step `stop`.
fn stopped(dir: &Path, log: &Path, stop: u64) {
    let mut opts = options(dir, log);
    opts.stop_after_step = Some(stop);
    match run_scenario(&common::meshfree_four(), &opts) {
        Err(RunError::Interrupted { step, .. }) => assert_eq!(step, stop),
        other => panic!("expected an interruption at {stop}, got {other:?}"),
    }
}

/// Resumes the run of `dir/checkpoint.bin` with `--mcap log`, to its end or stopped after step
/// `stop_after`.
fn resume(dir: &Path, log: &Path, stop_after: Option<u64>) -> Result<(), RunError> {
    let ckpt = dir.join("checkpoint.bin");
    let c = MeshfreeCheckpoint::read(&ckpt).unwrap();
    let mut opts = options(dir, log);
    opts.stop_after_step = stop_after;
    resume_run(&c, &ckpt, &opts).map(|_| ())
}

/// `sdem resume CHECKPOINT --mcap LOG --quiet`, which must succeed: its stderr.
fn resume_cli(checkpoint: &Path, log: &Path) -> String {
    let o = sdem()
        .arg("resume")
        .arg(checkpoint)
        .arg("--mcap")
        .arg(log)
        .arg("--quiet")
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&o.stderr).into_owned();
    assert!(o.status.success(), "{stderr}");
    stderr
}

#[test]
fn a_stopped_then_resumed_meshfree_log_is_the_uninterrupted_log() {
    let reference = reference();
    // Off a row step, before the first frame; at a row and checkpoint step in the isotropic
    // phase, then again in the servo phase.
    for stops in [vec![5], vec![1], vec![4, 11]] {
        let dir = common::temp_dir("mfmcap", &format!("stop{}", stops[0]));
        let log = dir.join("run.mcap");
        stopped(&dir, &log, stops[0]);
        let t = Trajectory::open(&log).unwrap();
        assert_eq!(t.summary_info("status"), Some("interrupted"));
        for &next in &stops[1..] {
            let e = resume(&dir, &log, Some(next)).unwrap_err();
            assert!(matches!(e, RunError::Interrupted { .. }), "{e}");
            let t = Trajectory::open(&log).unwrap();
            assert_eq!(t.summary_info("status"), Some("interrupted"));
            let c = MeshfreeCheckpoint::read(&dir.join("checkpoint.bin")).unwrap();
            assert_eq!(t.frame_count() as u64, c.loop_state.macro_rows);
            assert!(t.frame(-1).unwrap().step <= next);
        }
        resume(&dir, &log, None).unwrap();
        common::mcap::assert_same_log(reference, &log, 8);
        let tmp = dir.join("run.mcap.resume.tmp");
        assert!(!tmp.exists(), "{} left behind", tmp.display());
        std::fs::remove_dir_all(&dir).ok();
    }
}

#[test]
fn an_unfinished_meshfree_log_is_continued_to_the_uninterrupted_log() {
    let reference = reference();
    // A run stopped at step 5 and resumed to its end: its log holds the whole run, frames after
    // the step-5 checkpoint (kept aside with its macro.csv) included.
    let dir = common::temp_dir("mfmcap", "unfinished");
    let log = dir.join("run.mcap");
    stopped(&dir, &log, 5);
    let kept = dir.join("kept");
    std::fs::create_dir_all(&kept).unwrap();
    for file in ["checkpoint.bin", "macro.csv"] {
        std::fs::copy(dir.join(file), kept.join(file)).unwrap();
    }
    let rows = MeshfreeCheckpoint::read(&kept.join("checkpoint.bin"))
        .unwrap()
        .loop_state
        .macro_rows;
    resume(&dir, &log, None).unwrap();
    let whole = std::fs::read(&log).unwrap();
    // The log cut as a killed writer leaves it: after its last chunk (and that chunk's message
    // indexes), without the `sdem.summary` metadata, the data end and the summary section;
    // then in the middle of that chunk.
    let summary = ::mcap::Summary::read(&whole).unwrap().expect("a summary");
    let last = summary.chunk_indexes.last().unwrap();
    let chunks_end =
        (last.chunk_start_offset + last.chunk_length + last.message_index_length) as usize;
    let in_last_chunk = (last.chunk_start_offset + last.chunk_length / 2) as usize;
    let mut beyond = 0;
    for cut in [chunks_end, in_last_chunk] {
        std::fs::write(&log, &whole[..cut]).unwrap();
        let scan = scan_log(&log, |_, _| Ok(true)).unwrap();
        assert!(!scan.finished);
        let frames = scan.frames.len() as u64;
        assert!(frames >= rows, "{frames} frames, {rows} in the checkpoint");
        if frames > rows {
            beyond += 1;
        }
        eprintln!(
            "cut at byte {cut} of {}: {frames} frames, {rows} in the checkpoint",
            whole.len()
        );
        for file in ["checkpoint.bin", "macro.csv"] {
            std::fs::copy(kept.join(file), dir.join(file)).unwrap();
        }
        let stderr = resume_cli(&dir.join("checkpoint.bin"), &log);
        assert!(stderr.contains("continuing the MCAP log"), "{stderr}");
        assert!(stderr.contains("the log was unfinished"), "{stderr}");
        common::mcap::assert_same_log(reference, &log, 8);
    }
    assert_eq!(beyond, 2, "a cut log held no frames after its checkpoint");
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn a_missing_log_is_started_with_the_continued_part_of_a_meshfree_run() {
    let reference = Trajectory::open(reference()).unwrap();
    let dir = common::temp_dir("mfmcap", "missing");
    stopped(&dir, &dir.join("first.mcap"), 5);
    let log = dir.join("continued.mcap");
    let stderr = resume_cli(&dir.join("checkpoint.bin"), &log);
    assert!(stderr.contains("does not exist"), "{stderr}");
    let t = Trajectory::open(&log).unwrap();
    assert_eq!(t.summary_info("status"), Some("complete"));
    assert_eq!(t.frame(0).unwrap().step, 6);
    // The reference's frames after step 5, bit for bit.
    let after: Vec<i64> = (0..reference.frame_count() as i64)
        .filter(|&k| reference.frame(k).unwrap().step > 5)
        .collect();
    assert_eq!(t.frame_count(), after.len());
    for (k, &r) in after.iter().enumerate() {
        assert_eq!(
            format!("{:?}", t.frame(k as i64).unwrap()),
            format!("{:?}", reference.frame(r).unwrap()),
            "frame {k}"
        );
    }
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn a_meshfree_resume_refuses_the_log_of_another_run() {
    let base = common::temp_dir("mfmcap", "foreign");
    let dir = base.join("run");
    let log = dir.join("run.mcap");
    stopped(&dir, &log, 5);
    // The log of the same scenario with another seed, and the log of an SDEM run.
    let other = base.join("other");
    let mut s = common::meshfree_four();
    s.seed += 1;
    let mut o = options(&other, &other.join("other.mcap"));
    o.stop_after_step = Some(5);
    assert!(run_scenario(&s, &o).is_err());
    let sdem_dir = base.join("sdem");
    let mut o = options(&sdem_dir, &sdem_dir.join("sdem.mcap"));
    o.stop_after_step = Some(100);
    assert!(run_scenario(&common::small_compaction(), &o).is_err());
    for (foreign, words) in [
        (
            other.join("other.mcap"),
            &["not the log of this run", "seed"][..],
        ),
        (sdem_dir.join("sdem.mcap"), &["no /contours channel"][..]),
    ] {
        let bytes = std::fs::read(&foreign).unwrap();
        std::fs::write(&log, &bytes).unwrap();
        let e = resume(&dir, &log, None).unwrap_err().to_string();
        eprintln!("{}: {e}", foreign.display());
        for w in [log.to_str().unwrap(), "cannot continue"]
            .iter()
            .chain(words)
        {
            assert!(e.contains(w), "{e:?} lacks {w:?}");
        }
        // Each key that differs is named once.
        assert!(e.matches("seed:").count() <= 1, "{e}");
        assert!(std::fs::read(&log).unwrap() == bytes, "log changed: {e}");
        assert!(!dir.join("run.mcap.resume.tmp").exists());
    }
    std::fs::remove_dir_all(&base).ok();
}
