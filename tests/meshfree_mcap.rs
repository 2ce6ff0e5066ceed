//! Trajectory logs of meshfree runs: `sdem run --mcap` writes each grain's boundary-node
//! contour (`/contours`) with its mean stress; the log reads back equal to `grains.csv`, and
//! `sdem render` / `sdem inspect` read it.

use sdem::boundary::walls::{BOTTOM, LEFT, RIGHT, TOP};
use sdem::output::mcap::{
    TOPIC_CONTOURS, TOPIC_GRAINS, TOPIC_MACRO, TOPIC_SCENE, TOPIC_WALLS, Trajectory, scan_log,
};
use sdem::run::meshfree::Meshfree;
use sdem::scenario::Scenario;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;

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

#[test]
fn a_meshfree_run_does_not_continue_a_log() {
    // Resuming needs meshfree checkpoints: the log side refuses clearly until then.
    use sdem::output::mcap::{ContinueFrom, McapSettings};
    use sdem::run::RunError;
    use sdem::run::Simulation;
    let scenario = Scenario::parse(FOUR_DISCS, "four.ron").unwrap();
    let sim = Meshfree::new(&scenario).unwrap();
    let dir = std::env::temp_dir().join(format!("sdem-mfmcap-cont-{}", std::process::id()));
    let settings = McapSettings::new(dir.join("t.mcap"));
    let from = ContinueFrom { step: 3, frames: 1 };
    let Err(e) = sim.open_log(&settings, &scenario, Some(from)) else {
        panic!("a continued meshfree log was opened");
    };
    assert!(matches!(e, RunError::Setup(_)), "{e:?}");
    assert!(e.to_string().contains("meshfree"), "{e}");
    assert!(!dir.join("t.mcap").exists());
}
