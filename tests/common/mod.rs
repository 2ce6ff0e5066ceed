//! Scaffolding shared by the integration tests that run, stop and resume small compactions;
//! [`meshfree`]: the stacked-disc column of the multibody meshfree tests; [`mcap`]: logs
//! compared message for message.
#![allow(dead_code)] // each test binary uses its own subset

pub mod mcap;
pub mod meshfree;
pub mod rolling;

use sdem::grain::Grain;
use sdem::run::checkpoint::Checkpoint;
use sdem::run::{RunError, RunOptions, run_scenario};
use sdem::scenario::Scenario;
use std::path::{Path, PathBuf};

/// ~6000 steps: a fast isotropic compaction of 200 grains through jamming, then a relaxation
/// phase; a macro.csv row (and an MCAP frame) every 50 steps.
pub const SMALL_COMPACTION: &str = r#"
Scenario(
    name: "small_compaction",
    sample: (count: 200, box_width: 0.45, box_height: 0.45,
             radii: Gaussian(mean: 0.012, std_dev: 0.0024, min: 0.008, max: 0.016)),
    material: (young: 1.0, poisson: 0.5, density: 1.0),
    loading: [
        Isotropic(rate: Constant(5e-2), until: PackingFraction(0.86)),
        Relax(until: Steps(1000)),
    ],
    output: (every: 50),
)
"#;

/// [`SMALL_COMPACTION`], parsed and validated.
pub fn small_compaction() -> Scenario {
    let s = Scenario::parse(SMALL_COMPACTION, "small.ron").unwrap();
    s.validate().unwrap();
    s
}

/// 4 coarse meshfree discs (16 boundary nodes), 16 steps: an isotropic compression with the
/// walls against the grains from the first step, then a servo phase (its wall velocities come
/// from the wall stresses of the step before, so the contact elements of the last step must be
/// restored exactly), the first grain-grain contacts near its end. A `macro.csv` row (and an
/// MCAP frame) every 2 steps and at jamming; well under 0.1 s a step in release.
pub const MESHFREE_FOUR: &str = r#"
Scenario(
    name: "mf_ckpt",
    seed: 3,
    sample: (count: 4, box_width: 0.34, box_height: 0.34,
             radii: Uniform(min: 0.06, max: 0.07)),
    material: (young: 1.0, poisson: 0.3, density: 1.0),
    model: Meshfree((boundary_nodes: 16, rayleigh_alpha: 5.0)),
    time_step: Fixed(0.01),
    loading: [
        Isotropic(rate: Constant(2.0), until: PackingFraction(0.6)),
        Servo(sxx: 0.1, syy: 0.1, gain: 0.5, max_rate: 2.0, until: Steps(100)),
    ],
    output: (every: 2, max_steps: 16),
)
"#;

/// [`MESHFREE_FOUR`], parsed and validated.
pub fn meshfree_four() -> Scenario {
    let s = Scenario::parse(MESHFREE_FOUR, "mf_ckpt.ron").unwrap();
    s.validate().unwrap();
    s
}

/// A fresh, empty folder for one test: `sdem-<prefix>-<pid>-<name>` in the temp dir, removed
/// with everything in it when the value is dropped (also when the test fails).
pub fn temp_dir(prefix: &str, name: &str) -> TempDir {
    let dir = std::env::temp_dir().join(format!("sdem-{prefix}-{}-{name}", std::process::id()));
    std::fs::remove_dir_all(&dir).ok();
    std::fs::create_dir_all(&dir).unwrap();
    TempDir(dir)
}

/// A test's scratch folder ([`temp_dir`]); reads as the folder's path.
pub struct TempDir(PathBuf);

impl TempDir {
    /// The folder's path, the folder kept: for a folder that several tests of one binary share
    /// through a static, which is never dropped.
    pub fn keep(self) -> PathBuf {
        let path = self.0.clone();
        std::mem::forget(self);
        path
    }
}

impl std::ops::Deref for TempDir {
    type Target = Path;
    fn deref(&self) -> &Path {
        &self.0
    }
}

impl AsRef<Path> for TempDir {
    fn as_ref(&self) -> &Path {
        &self.0
    }
}

impl AsRef<std::ffi::OsStr> for TempDir {
    fn as_ref(&self) -> &std::ffi::OsStr {
        self.0.as_os_str()
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        std::fs::remove_dir_all(&self.0).ok();
    }
}

/// Run options writing into `out` with a checkpoint every `every` steps.
pub fn checkpointed(out: &Path, every: u64) -> RunOptions {
    RunOptions {
        out_dir: out.to_path_buf(),
        checkpoint_every: every,
        ..Default::default()
    }
}

/// Every degree of freedom of every grain, as bits: equal means bitwise identical.
pub fn grain_bits(g: &[Grain]) -> Vec<[u64; 13]> {
    g.iter().map(|g| g.to_array().map(f64::to_bits)).collect()
}

/// Asserts that two finished runs wrote the same `macro.csv` and `grains.csv`, byte for byte,
/// and left checkpoints with bitwise the same grains; returns the two checkpoints for the
/// caller's own comparisons.
pub fn assert_same_run(a: &Path, b: &Path) -> (Checkpoint, Checkpoint) {
    for file in ["macro.csv", "grains.csv"] {
        let x = std::fs::read(a.join(file)).unwrap();
        let y = std::fs::read(b.join(file)).unwrap();
        assert!(x == y, "{file} differs between {a:?} and {b:?}");
    }
    let (ca, cb) = (
        Checkpoint::read(&a.join("checkpoint.bin")).unwrap(),
        Checkpoint::read(&b.join("checkpoint.bin")).unwrap(),
    );
    assert_eq!(grain_bits(&ca.grains), grain_bits(&cb.grains));
    (ca, cb)
}

/// Runs `f` on a rayon pool of `threads` threads.
pub fn with_threads<T: Send>(threads: usize, f: impl FnOnce() -> T + Send) -> T {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap()
        .install(f)
}

/// Runs `scenario` with `options` told to stop after step `stop`; asserts the run reports that
/// interruption, and returns the checkpoint it left and the checkpoint's path.
pub fn run_interrupted_at(
    scenario: &Scenario,
    options: &RunOptions,
    stop: u64,
) -> (Checkpoint, PathBuf) {
    let mut options = options.clone();
    options.stop_after_step = Some(stop);
    match run_scenario(scenario, &options) {
        Err(RunError::Interrupted { step, .. }) => assert_eq!(step, stop),
        other => panic!("expected an interruption at {stop}, got {other:?}"),
    }
    let path = options.out_dir.join("checkpoint.bin");
    (Checkpoint::read(&path).unwrap(), path)
}
