//! The `sdem` command line (SPEC §12).

use anyhow::{Context, Result, anyhow, bail};
use clap::{Parser, Subcommand};
use sdem::output::lock::OutputLock;
use sdem::output::mcap::{McapSettings, Trajectory};
use sdem::output::plot::{MacroSeries, PlotFormat, plot_macro};
use sdem::output::render::{RenderOptions, render_frame};
use sdem::output::vtk::{DEFAULT_OUTLINE_NODES, VtkOptions, VtkWriter};
use sdem::run::checkpoint::AnyCheckpoint;
use sdem::run::{RunOptions, resume_run, run_scenario};
use sdem::scenario::{CheckpointInterval, Scenario};
use std::io::IsTerminal;
use std::path::{Path, PathBuf};

/// Large arrays in huge pages: 1.02-1.05 times the step rate at 10^5 grains (see the module).
#[global_allocator]
static ALLOCATOR: sdem::huge_pages::HugePageAllocator = sdem::huge_pages::HugePageAllocator;

#[derive(Parser)]
#[command(
    name = "sdem",
    version,
    about = "Soft Discrete Element Method: 2D assemblies of highly deformable grains"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Run a scenario: writes DIR/macro.csv, DIR/grains.csv and DIR/summary.txt.
    Run {
        /// Scenario file (RON), e.g. scenarios/isotropic_A.ron.
        scenario: PathBuf,
        /// Output directory (default: out/<scenario name>).
        #[arg(long)]
        out: Option<PathBuf>,
        /// Worker threads (default: all cores). Results are identical for any count.
        #[arg(long)]
        threads: Option<usize>,
        /// No progress lines.
        #[arg(long)]
        quiet: bool,
        /// Also write the trajectory (grains, contacts, walls, macro rows, a Foxglove scene) as
        /// an MCAP log, one frame per row of macro.csv (a meshfree run logs each grain's
        /// deformed contour in place of grains and contacts).
        #[arg(long, value_name = "FILE")]
        mcap: Option<PathBuf>,
        /// Write the Foxglove `/scene` channel every K frames (0: never; default: every frame up
        /// to 10^4 grains, every ceil(N/10^4)-th frame above).
        #[arg(long, value_name = "K", requires = "mcap")]
        mcap_scene_every: Option<u64>,
        /// Also write the trajectory for ParaView: DIR/grains.pvd, DIR/contacts.pvd and
        /// DIR/boundary.pvd, time series of VTK PolyData files (DIR/vtp/*.vtp), one frame per
        /// row of macro.csv (see `sdem export --vtk`).
        #[arg(long, value_name = "DIR")]
        vtk: Option<PathBuf>,
        /// Keep the latest checkpoint in DIR/checkpoint.bin, written every STEPS steps, on
        /// Ctrl-C / SIGTERM (then the run stops) and at the end (see `sdem resume`). Overrides
        /// the scenario's output.checkpoint.
        #[arg(long, value_name = "STEPS", value_parser = clap::value_parser!(u64).range(1..))]
        checkpoint_every: Option<u64>,
        /// Like --checkpoint-every, but every S seconds of wall-clock time (after the first step
        /// that ends S seconds after the last checkpoint). Results do not depend on it.
        #[arg(long, value_name = "S", value_parser = parse_seconds, conflicts_with = "checkpoint_every", allow_negative_numbers = true)]
        checkpoint_every_seconds: Option<f64>,
    },
    /// Continue a run from its checkpoint (written by `sdem run --checkpoint-every`):
    /// macro.csv goes on from the checkpoint's step without missing or repeated rows.
    Resume {
        /// The checkpoint, e.g. out/isotropic_A/checkpoint.bin.
        checkpoint: PathBuf,
        /// Output directory (default: the checkpoint's directory).
        #[arg(long)]
        out: Option<PathBuf>,
        /// Worker threads (default: all cores). Results are identical for any count.
        #[arg(long)]
        threads: Option<usize>,
        /// No progress lines.
        #[arg(long)]
        quiet: bool,
        /// Continue the MCAP log FILE (the interrupted run's, finished or left unfinished by a
        /// kill): it ends up holding exactly the frames of the uninterrupted run. A FILE that
        /// does not exist gets the continued part only.
        #[arg(long, value_name = "FILE")]
        mcap: Option<PathBuf>,
        /// Checkpoint interval in steps (default: the interrupted run's).
        #[arg(long, value_name = "STEPS", value_parser = clap::value_parser!(u64).range(1..))]
        checkpoint_every: Option<u64>,
        /// Checkpoint interval in wall-clock seconds (default: the interrupted run's).
        #[arg(long, value_name = "S", value_parser = parse_seconds, conflicts_with = "checkpoint_every", allow_negative_numbers = true)]
        checkpoint_every_seconds: Option<f64>,
    },
    /// Time the SDEM step on a dense packing (phi ~ 0.9, nu = 0.5, dbeta = 1 degree), at the full
    /// SDEM level or (`--model`) another. The environment variable SDEM_SIMD (auto, avx,
    /// avx512) picks the vector instructions of every command; results are the same bits.
    Bench {
        /// Number of grains (rounded up to full lattice rows).
        #[arg(long, default_value_t = 10_000)]
        grains: usize,
        /// Timed steps (after the warm-up steps).
        #[arg(long, default_value_t = 200)]
        steps: u64,
        /// Untimed steps before the timed ones. The packing's first few hundred steps are its
        /// release from the lattice's overlaps: the grains at its edges cross the half spacing
        /// to the walls and rebuild the neighbour list every few steps; a long warm-up times a
        /// settled packing, as LAMMPS's bench deck does (benches/lammps/).
        #[arg(long, default_value_t = 20)]
        warmup: u64,
        #[arg(long)]
        threads: Option<usize>,
        /// Contour resolution dbeta in degrees; 0 for the exact ellipses (dbeta -> 0).
        #[arg(long, default_value_t = 1.0)]
        resolution: f64,
        /// Coulomb friction coefficient of every contact (0: frictionless).
        #[arg(long, default_value_t = 0.0)]
        friction: f64,
        /// Model level of every grain: rigid discs, discs with one volumetric strain (both with
        /// closed-form circle contacts), or the full SDEM grain.
        #[arg(long, value_enum, default_value_t = BenchModel::Full)]
        model: BenchModel,
        /// Time the steps of a run's own state instead of the dense packing: the world of an
        /// SDEM checkpoint (`sdem run ... --checkpoint-every`), stepped with the walls at their
        /// checkpointed velocities (the loading program's rate control and affine carry are
        /// left out). --grains, --resolution, --friction and --model do not apply.
        #[arg(long, value_name = "CHECKPOINT",
              conflicts_with_all = ["grains", "resolution", "friction", "model"])]
        from: Option<PathBuf>,
    },
    /// Fit the secant contact law (a, b) to single-grain meshfree compressions (SPEC §10):
    /// writes DIR/calibration.csv, DIR/calibration_svk.csv and DIR/calibration.svg. With
    /// --assembly: fit it to reference runs of whole assemblies instead (writes
    /// DIR/assembly_fit.csv, DIR/assembly_fit.txt and the runs in DIR/runs/).
    Calibrate {
        /// Poisson's ratios, comma separated (default 0,0.1,0.2,0.3,0.4,0.45,0.49).
        #[arg(long, value_delimiter = ',')]
        nu: Option<Vec<f64>>,
        /// An SDEM scenario to fit on (repeatable: one pair (a, b) for all of them), each paired
        /// in order with a --reference run of the same packing, walls, loading and material
        /// (e.g. a meshfree run of tools/sdem_vs_meshfree.py, or the one-disc runs of
        /// tools/disc_column.py: a calibration with SDEM in the loop). The error is p_c's
        /// relative error at equal box strain over the loaded part (reference p_c >= 5e-3 E).
        #[arg(long, value_name = "SCENARIO", requires = "reference",
              conflicts_with_all = ["nu", "final_side", "steps", "boundary_nodes"])]
        assembly: Vec<PathBuf>,
        /// The reference run (directory or macro.csv) of each --assembly scenario.
        #[arg(long, value_name = "RUN", requires = "assembly")]
        reference: Vec<PathBuf>,
        /// With --assembly: the grid of a, comma separated (default 0.45,0.5,0.58,0.65,0.75,0.85,1,1.2).
        #[arg(
            long,
            value_delimiter = ',',
            requires = "assembly",
            allow_negative_numbers = true
        )]
        a: Option<Vec<f64>>,
        /// With --assembly: the grid of b, comma separated (default 0.5,1,1.5,2,3,4).
        #[arg(
            long,
            value_delimiter = ',',
            requires = "assembly",
            allow_negative_numbers = true
        )]
        b: Option<Vec<f64>>,
        /// With --assembly: Nelder–Mead evaluations from the grid's best pair (0: the grid only).
        #[arg(long, default_value_t = 20, requires = "assembly")]
        refine: usize,
        /// Output directory.
        #[arg(long, default_value = "out/calibration")]
        out: PathBuf,
        /// Final box side (the disc has diameter 1).
        #[arg(long, default_value_t = 0.90)]
        final_side: f64,
        /// Load steps from side 1 to the final side.
        #[arg(long)]
        steps: Option<usize>,
        /// Boundary nodes of the disc (a multiple of 4): the nodal density.
        #[arg(long)]
        boundary_nodes: Option<usize>,
        #[arg(long)]
        threads: Option<usize>,
    },
    /// Check a scenario file and print its warnings and derived settings, without running it.
    Check { scenario: PathBuf },
    /// Summarise a trajectory log (MCAP): channels, frames, time span, sizes.
    Inspect {
        /// The log written by `sdem run --mcap FILE`.
        file: PathBuf,
    },
    /// Draw one frame of a trajectory log: deformed grains with their flat contacts, coloured
    /// by mean stress, with a colour bar (PNG, or SVG if OUT ends in .svg).
    Render {
        file: PathBuf,
        /// Frame number, from 0; negative counts from the end (-1: the last, the default).
        #[arg(long, allow_negative_numbers = true, conflicts_with_all = ["step", "jamming"])]
        frame: Option<i64>,
        /// The first frame at or after this step.
        #[arg(long, conflicts_with = "jamming")]
        step: Option<u64>,
        /// The frame at the run's jamming point.
        #[arg(long)]
        jamming: bool,
        /// Output picture.
        #[arg(long)]
        out: PathBuf,
        /// Pixels along the longer side of the box.
        #[arg(long, default_value_t = 1200)]
        size: u32,
        /// Top of the colour scale (mean stress, compression positive; default: the frame's
        /// 99th percentile).
        #[arg(long)]
        stress_max: Option<f64>,
        /// Show only this part of the sample: X0,Y0,X1,Y1 (default: the whole box).
        #[arg(long, value_name = "X0,Y0,X1,Y1", value_parser = parse_region)]
        region: Option<Region>,
    },
    /// Export a trajectory log for ParaView: every frame as VTK PolyData (.vtp) files in
    /// DIR/vtp/, listed with their simulated times in DIR/grains.pvd (deformed grain outlines
    /// with their stresses and DoF), DIR/contacts.pvd (the contact network) and
    /// DIR/boundary.pvd (walls or periodic cell). Open the .pvd files in ParaView.
    Export {
        /// The log written by `sdem run --mcap FILE`.
        file: PathBuf,
        /// Output directory of the VTK files.
        #[arg(long, value_name = "DIR")]
        vtk: PathBuf,
        /// Nodes of an SDEM grain's contour polygon before its flat contact cuts.
        #[arg(long, default_value_t = DEFAULT_OUTLINE_NODES as u32,
              value_parser = clap::value_parser!(u32).range(8..=100_000))]
        outline_nodes: u32,
        /// Export every K-th frame only (and always the last).
        #[arg(long, value_name = "K", default_value_t = 1,
              value_parser = clap::value_parser!(u64).range(1..))]
        every: u64,
    },
    /// Write a sample file with its grains' rows strip by strip (strips one mean diameter wide
    /// along the shorter side, back and forth), the spatial order SDEM steps fastest: a file
    /// of 10^4 grains or more in a scattered order steps about half as fast, and draws a
    /// warning that points here. Each row is kept as written (the same grains to the last
    /// digit); the header and comment lines come first.
    SortSample {
        /// The sample file (CSV, as a scenario's `sample.file` reads it).
        input: PathBuf,
        /// The sorted file to write; may be INPUT itself (written to a temporary file first).
        output: PathBuf,
    },
    /// Plot the macroscopic curves (p_c against phi with eq. 69, z and q_c against p_c) from a
    /// run directory, its macro.csv or a trajectory log.
    Plot {
        /// A run directory, a macro.csv or an .mcap log.
        source: PathBuf,
        /// Output directory for p_phi, z_p and q_p pictures.
        #[arg(long)]
        out: PathBuf,
        /// SVG instead of PNG.
        #[arg(long)]
        svg: bool,
    },
}

/// `sdem bench --model`: the model level of every grain.
#[derive(Debug, Clone, Copy, clap::ValueEnum)]
enum BenchModel {
    Rigid,
    Volumetric,
    Full,
}

impl BenchModel {
    fn level(self) -> sdem::grain::ModelLevel {
        match self {
            Self::Rigid => sdem::grain::ModelLevel::Rigid,
            Self::Volumetric => sdem::grain::ModelLevel::Volumetric,
            Self::Full => sdem::grain::ModelLevel::Full,
        }
    }
}

/// A rectangle of the sample, `(lower left, upper right)`.
#[derive(Debug, Clone, Copy)]
struct Region((glam::DVec2, glam::DVec2));

fn parse_region(text: &str) -> std::result::Result<Region, String> {
    let v: Vec<f64> = text
        .split(',')
        .map(|x| x.trim().parse::<f64>())
        .collect::<std::result::Result<_, _>>()
        .map_err(|e| format!("`{text}`: {e}"))?;
    match v[..] {
        [x0, y0, x1, y1] if x1 > x0 && y1 > y0 && v.iter().all(|x| x.is_finite()) => {
            Ok(Region((glam::DVec2::new(x0, y0), glam::DVec2::new(x1, y1))))
        }
        _ => Err(format!(
            "`{text}`: expected X0,Y0,X1,Y1 with X1 > X0 and Y1 > Y0"
        )),
    }
}

/// "1 thread", "2 threads".
fn thread_count(pool: &rayon::ThreadPool) -> String {
    match pool.current_num_threads() {
        1 => "1 thread".to_string(),
        n => format!("{n} threads"),
    }
}

/// A checkpoint interval in seconds: a finite number > 0.
fn parse_seconds(text: &str) -> std::result::Result<f64, String> {
    match text.trim().parse::<f64>() {
        Ok(s) if s.is_finite() && s > 0.0 => Ok(s),
        Ok(s) => Err(format!(
            "{s} seconds: the checkpoint interval must be a finite number of seconds > 0"
        )),
        Err(e) => Err(format!("`{text}`: {e} (expected a number of seconds > 0)")),
    }
}

/// The checkpoint interval of a run: the command line's, else the scenario's; (steps, seconds).
fn checkpoint_interval(
    steps: Option<u64>,
    seconds: Option<f64>,
    default: Option<CheckpointInterval>,
) -> (u64, Option<f64>) {
    match (steps, seconds, default) {
        (Some(n), _, _) => (n, None),
        (None, Some(s), _) => (0, Some(s)),
        (None, None, Some(CheckpointInterval::EverySteps(n))) => (n, None),
        (None, None, Some(CheckpointInterval::EverySeconds(s))) => (0, Some(s)),
        (None, None, None) => (0, None),
    }
}

fn thread_pool(threads: Option<usize>) -> Result<rayon::ThreadPool> {
    let mut builder = rayon::ThreadPoolBuilder::new();
    if let Some(n) = threads {
        if n == 0 {
            bail!("--threads must be at least 1");
        }
        builder = builder.num_threads(n);
    }
    builder.build().context("starting the worker threads")
}

fn load(path: &std::path::Path) -> Result<Scenario> {
    let (scenario, warnings) = Scenario::load(path)?;
    for w in &warnings {
        eprintln!("warning: {w}");
    }
    Ok(scenario)
}

fn main() -> std::process::ExitCode {
    match run(Cli::parse()) {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            // One readable chain of causes; no backtrace for a user's mistake.
            eprintln!("error: {e:#}");
            std::process::ExitCode::FAILURE
        }
    }
}

fn run(cli: Cli) -> Result<()> {
    // A tuning knob, not physics (every choice gives the same bits), but a misspelt one should
    // not pass for the default.
    sdem::lanes::Simd::from_env()?;
    match cli.command {
        Command::Run {
            scenario,
            out,
            threads,
            quiet,
            mcap,
            mcap_scene_every,
            vtk,
            checkpoint_every,
            checkpoint_every_seconds,
        } => {
            let parsed = load(&scenario)?;
            let (every, seconds) = checkpoint_interval(
                checkpoint_every,
                checkpoint_every_seconds,
                parsed.output.checkpoint,
            );
            let out_dir = out.unwrap_or_else(|| PathBuf::from("out").join(&parsed.name));
            // One run per output directory, and one that can be written, before anything runs.
            let _lock = OutputLock::acquire(&out_dir)?;
            let pool = thread_pool(threads)?;
            let step_note = match parsed.model {
                sdem::scenario::Model::Meshfree(m) => {
                    let kind = match m.scheme {
                        sdem::meshfree::TimeScheme::CentralDifference => "explicit",
                        _ => "implicit",
                    };
                    format!("{kind} meshfree, {:?} scheme", m.scheme)
                }
                _ => format!(
                    "{:.2} x critical",
                    parsed.time_step_value() / parsed.critical_time_step()
                ),
            };
            eprintln!(
                "sdem: {} — {} grains, dt = {:.3e} ({step_note}), {}, output in {}",
                parsed.name,
                parsed.sample.grain_count(),
                parsed.time_step_value(),
                thread_count(&pool),
                out_dir.display()
            );
            if let Some(a) = parsed.parameters().adaptive {
                if a.dt[1] == a.dt[0] {
                    // Incompressible grains: the volumetric level takes the rigid step.
                    eprintln!(
                        "sdem: adaptive model level: dt = {:.3e} while no grain is at the full level, {:.3e} once one is",
                        a.dt[0], a.dt[2]
                    );
                } else {
                    eprintln!(
                        "sdem: adaptive model level: dt = {:.3e} while every grain is rigid, {:.3e} once one deforms",
                        a.dt[0], a.dt[2]
                    );
                }
                if a.multi_rate {
                    eprintln!(
                        "sdem: multi-rate cycles: while some grains deform and a quarter or more are rigid, the rigid grains out of their reach take one step of {:.3e} to their two of {:.3e}",
                        2.0 * a.dt[2],
                        a.dt[2]
                    );
                }
            }
            // On a terminal: a progress bar (after a few seconds); otherwise a line every 30 s.
            let terminal = std::io::stderr().is_terminal();
            let options = RunOptions {
                out_dir: out_dir.clone(),
                progress_seconds: (!quiet && !terminal).then_some(30.0),
                progress_bar: !quiet && terminal,
                mcap: mcap.map(|path| McapSettings {
                    path,
                    scene_every: mcap_scene_every,
                }),
                vtk,
                checkpoint_every: every,
                checkpoint_seconds: seconds,
                stop: (every > 0 || seconds.is_some()).then(stop_signals::install),
                stop_after_step: None,
            };
            let summary = pool.install(|| run_scenario(&parsed, &options))?;
            report(&summary, &options, &out_dir);
        }
        Command::Resume {
            checkpoint,
            out,
            threads,
            quiet,
            mcap,
            checkpoint_every,
            checkpoint_every_seconds,
        } => {
            let saved = AnyCheckpoint::read(&checkpoint)?;
            let out_dir = out.unwrap_or_else(|| match checkpoint.parent() {
                Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
                _ => PathBuf::from("."),
            });
            let _lock = OutputLock::acquire(&out_dir)?;
            let pool = thread_pool(threads)?;
            eprintln!(
                "sdem: resuming {} at step {} (t = {:.4e}), {}, output in {}",
                saved.scenario().name,
                saved.step(),
                saved.time(),
                thread_count(&pool),
                out_dir.display()
            );
            let terminal = std::io::stderr().is_terminal();
            let (every, seconds) = match (checkpoint_every, checkpoint_every_seconds) {
                (None, None) => saved.checkpoint_interval(),
                (steps, seconds) => checkpoint_interval(steps, seconds, None),
            };
            let options = RunOptions {
                out_dir: out_dir.clone(),
                progress_seconds: (!quiet && !terminal).then_some(30.0),
                progress_bar: !quiet && terminal,
                mcap: mcap.map(|path| McapSettings {
                    path,
                    scene_every: None,
                }),
                vtk: None,
                checkpoint_every: every,
                checkpoint_seconds: seconds,
                stop: (every > 0 || seconds.is_some()).then(stop_signals::install),
                stop_after_step: None,
            };
            let summary = pool.install(|| resume_run(&saved, &checkpoint, &options))?;
            report(&summary, &options, &out_dir);
        }
        Command::Bench {
            grains,
            steps,
            warmup,
            threads,
            resolution,
            friction,
            model,
            from,
        } => {
            if grains < 4 || steps == 0 {
                bail!("--grains must be at least 4 and --steps at least 1");
            }
            if !(friction.is_finite() && friction >= 0.0) {
                bail!("--friction {friction}: a friction coefficient is a finite number >= 0");
            }
            let from_checkpoint = match &from {
                Some(path) => match AnyCheckpoint::read(path)? {
                    AnyCheckpoint::Sdem(c) => Some(
                        sdem::run::world_from_checkpoint(&c)
                            .map_err(|e| anyhow!("{}: {e}", path.display()))?,
                    ),
                    AnyCheckpoint::Meshfree(_) => bail!(
                        "{}: a meshfree run's checkpoint; sdem bench times the SDEM step only",
                        path.display()
                    ),
                },
                None => None,
            };
            let pool = thread_pool(threads)?;
            let scene = match &from {
                Some(path) => format!("checkpoint: {}", path.display()),
                None => format!("model: {:?}", model.level()),
            };
            let result = pool.install(|| {
                let mut world = match from_checkpoint {
                    Some(world) => world,
                    None => {
                        let mut world = sdem::run::bench::dense_packing(grains, resolution);
                        sdem::run::bench::with_model(&mut world, model.level());
                        if friction > 0.0 {
                            sdem::run::bench::with_friction(&mut world, friction);
                        }
                        world
                    }
                };
                sdem::run::bench::run_bench(&mut world, warmup, steps)
            });
            // A compaction's checkpoint stepped long enough fails for a reason the step cannot
            // name: say it.
            let result = match (result, &from) {
                (Err(e), Some(path)) => bail!(
                    "{e}\n  (sdem bench steps the world of {} with its walls at their checkpointed \
                     velocities and without the loading's rate control: a box that was closing \
                     keeps closing, and a jammed packing squeezed long enough fails; time fewer \
                     steps)",
                    path.display()
                ),
                (result, _) => result?,
            };
            println!(
                "{}  grains: {}  steps: {}  threads: {}  phi: {:.3}  contacts per grain: {:.2}  candidate pairs per grain: {:.2}  neighbour-list builds: {} (skin {:.2} times its own)  seconds: {:.3}",
                scene,
                result.grains,
                result.steps,
                pool.current_num_threads(),
                result.phi,
                2.0 * result.contacts as f64 / result.grains as f64,
                result.candidate_pairs as f64 / result.grains as f64,
                result.neighbor_builds,
                result.skin_widening,
                result.seconds
            );
            println!("grain-steps/s: {:.4e}", result.grain_steps_per_second());
            println!("time by pass: {}", result.phases);
            println!("sweep: {}", result.sweeps);
            println!("vector lanes: {}", sdem::lanes::Simd::describe());
        }
        Command::Calibrate {
            assembly,
            reference,
            a,
            b,
            refine,
            out,
            threads,
            ..
        } if !assembly.is_empty() => {
            if assembly.len() != reference.len() {
                bail!(
                    "{} --assembly scenarios but {} --reference runs: give one reference per scenario, in the same order",
                    assembly.len(),
                    reference.len()
                );
            }
            let mut cases = Vec::new();
            for (path, reference) in assembly.iter().zip(&reference) {
                let stem = path
                    .file_stem()
                    .map(|s| s.to_string_lossy().into_owned())
                    .unwrap_or_else(|| "case".to_string());
                // The same scenario against two references: stem, stem_2, ...
                let taken = |l: &str| {
                    cases
                        .iter()
                        .any(|c: &sdem::calibration::AssemblyCase| c.label == l)
                };
                let mut label = stem.clone();
                let mut k = 1;
                while taken(&label) {
                    k += 1;
                    label = format!("{stem}_{k}");
                }
                let case = sdem::calibration::AssemblyCase::new(&label, load(path)?, reference)
                    .with_context(|| format!("the reference of {}", path.display()))?;
                cases.push(case);
            }
            let mut options = sdem::calibration::AssemblyOptions::new(cases, out);
            if let Some(a) = a {
                options.a_values = a;
            }
            if let Some(b) = b {
                options.b_values = b;
            }
            options.refine_evaluations = refine;
            let pool = thread_pool(threads)?;
            let report = pool.install(|| sdem::calibration::run_assembly_calibration(&options))?;
            println!("{report}");
        }
        Command::Calibrate {
            nu,
            out,
            final_side,
            steps,
            boundary_nodes,
            threads,
            ..
        } => {
            let mut options = sdem::calibration::CalibrateOptions {
                out_dir: out,
                final_box_side: final_side,
                ..Default::default()
            };
            if let Some(nus) = nu {
                options.nus = nus;
            }
            if let Some(steps) = steps {
                options.steps = steps;
            }
            if let Some(nodes) = boundary_nodes {
                options.boundary_nodes = nodes;
            }
            let pool = thread_pool(threads)?;
            let report = pool.install(|| sdem::calibration::run_calibration(&options))?;
            println!("{report}");
        }
        Command::Check { scenario } => {
            let parsed = load(&scenario)?;
            println!("{}: valid", scenario.display());
            match &parsed.sample.loaded {
                Some(l) => println!(
                    "sample: {} grains from {} (radii {:.4e} to {:.4e})",
                    l.grains.len(),
                    l.path.display(),
                    l.smallest_radius(),
                    l.grains.iter().map(|g| g.radius).fold(0.0, f64::max)
                ),
                None => println!("sample: {} generated grains", parsed.sample.grain_count()),
            }
            if let sdem::scenario::Model::Meshfree(m) = parsed.model {
                let built = sdem::run::meshfree::Meshfree::new(&parsed)?;
                let step_note = match built.assembly.explicit_data() {
                    Some(x) => format!(
                        "explicit: critical step {:.4e}, sub-steps of at most {:.4e}, {} per step",
                        x.critical_step,
                        x.sub_step(),
                        (parsed.time_step_value() / x.sub_step()).ceil()
                    ),
                    None => "implicit: no critical step".to_string(),
                };
                println!(
                    "model: meshfree, {} boundary nodes per grain, {:?} law, {:?} scheme ({step_note})",
                    m.boundary_nodes, m.law, m.scheme
                );
                let grains = &built.assembly.grains;
                let nodes: usize = grains.iter().map(|g| g.node_count()).sum();
                let gauss: usize = grains.iter().map(|g| g.gauss_count()).sum();
                println!(
                    "discretization: {} grains, {nodes} field nodes ({} to {} per grain), {} DoF, {gauss} Gauss points",
                    grains.len(),
                    grains.iter().map(|g| g.node_count()).min().unwrap_or(0),
                    grains.iter().map(|g| g.node_count()).max().unwrap_or(0),
                    built.assembly.dofs()
                );
            } else {
                println!(
                    "critical time step estimate: {:.4e}",
                    parsed.critical_time_step()
                );
            }
            println!("time step: {:.4e}", parsed.time_step_value());
            if !parsed.boundary.is_walls()
                && let Some(range) = parsed.interaction_range()
            {
                println!(
                    "boundary: periodic cell {} x {}; it must stay at least {:.4e} wide \
                     (twice the largest grain diameter + neighbour skin)",
                    parsed.sample.box_width,
                    parsed.sample.box_height,
                    2.0 * range
                );
            }
            if parsed.tangential_ratio() > 0.0 {
                let f = &parsed.contact.friction;
                let planes: Vec<String> = parsed
                    .planes
                    .iter()
                    .map(|p| p.friction.to_string())
                    .collect();
                let walls = if parsed.boundary.is_walls() {
                    format!(", {} at the box walls", f.walls)
                } else {
                    String::new()
                };
                println!(
                    "friction: mu = {} between grains{walls}{}; K_t = {} K_n, \
                     tangential damping {}",
                    f.grains,
                    if planes.is_empty() {
                        String::new()
                    } else {
                        format!(", {} at the planes", planes.join(", "))
                    },
                    f.stiffness_ratio,
                    f.damping
                );
            }
            if parsed.gravity != (0.0, 0.0) {
                println!("gravity: ({}, {})", parsed.gravity.0, parsed.gravity.1);
            }
            if parsed.deformation.mass_scale != 1.0 {
                println!(
                    "deformation mass scale: M_eps and M_alpha x {}",
                    parsed.deformation.mass_scale
                );
            }
            if let Some(a) = parsed.parameters().adaptive {
                println!(
                    "adaptive model level: time step {:.4e} while every grain is rigid (critical {:.4e})",
                    a.dt[0],
                    parsed.rigid_critical_time_step()
                );
            }
        }
        Command::Inspect { file } => inspect(&file)?,
        Command::Render {
            file,
            frame,
            step,
            jamming,
            out,
            size,
            stress_max,
            region,
        } => {
            let log = Trajectory::open(&file)?;
            let index = if jamming {
                let step: u64 = log
                    .summary_info("jamming_step")
                    .and_then(|s| s.parse().ok())
                    .with_context(|| {
                        format!("{}: the log records no jamming point", file.display())
                    })?;
                log.frame_at_step(step)? as i64
            } else if let Some(step) = step {
                log.frame_at_step(step)? as i64
            } else {
                frame.unwrap_or(-1)
            };
            let frame = log.frame(index)?;
            let options = RenderOptions {
                size,
                stress_max,
                title: log.run_info("scenario").unwrap_or_default().to_string(),
                region: region.map(|r| r.0),
            };
            let info = render_frame(&frame, &out, &options)
                .map_err(|e| anyhow::anyhow!("drawing {}: {e}", out.display()))?;
            eprintln!(
                "{}: frame {} (step {}), {} grains, colour scale 0 .. {:.3e}, {}x{} px",
                out.display(),
                log.resolve_frame(index)?,
                frame.step,
                info.grains,
                info.stress_max,
                info.width,
                info.height
            );
        }
        Command::Export {
            file,
            vtk,
            outline_nodes,
            every,
        } => export_vtk(&file, &vtk, outline_nodes as usize, every as usize)?,
        Command::SortSample { input, output } => {
            let name = input.display().to_string();
            let text = std::fs::read_to_string(&input)
                .with_context(|| format!("cannot read the sample file {name}"))?;
            let sorted = sdem::sample::order::sort_sample_text(&text, &name)?;
            sdem::run::checkpoint::write_atomic(&output, |file| {
                std::io::Write::write_all(file, sorted.text.as_bytes())
            })
            .with_context(|| format!("cannot write {}", output.display()))?;
            println!(
                "{}: {} grains strip by strip; rows one after the other lie {:.1} mean radii \
                 apart (median), {:.1} in {name}",
                output.display(),
                sorted.grains,
                sorted.step_after,
                sorted.step_before
            );
        }
        Command::Plot { source, out, svg } => {
            let series = MacroSeries::load(&source).map_err(anyhow::Error::msg)?;
            let format = if svg {
                PlotFormat::Svg
            } else {
                PlotFormat::Png
            };
            let written = plot_macro(&series, &out, format).map_err(anyhow::Error::msg)?;
            for path in written {
                println!("{}", path.display());
            }
        }
    }
    Ok(())
}

/// The end-of-run lines on stderr.
fn report(summary: &sdem::run::RunSummary, options: &RunOptions, out_dir: &Path) {
    eprintln!(
        "done: {} steps in {:.1} s ({:.3e} grain-steps/s)",
        summary.steps,
        summary.wall_seconds,
        summary.steps as f64 * summary.grains as f64 / summary.wall_seconds.max(1e-9)
    );
    if let Some(phases) = &summary.phase_seconds {
        eprintln!("time by pass: {phases}");
    }
    if let Some(sweeps) = summary.sweeps.filter(|t| t.two_passes > 0) {
        // Only where it cost something: a sample whose numbering makes the threads wait.
        eprintln!("sweep: {sweeps}");
    }
    if let Some(j) = summary.jamming {
        eprintln!(
            "jamming: step {}, phi_0 = {:.4}, z_0 = {:.3}, z_nr_0 = {:.3}",
            j.step, j.phi, j.z, j.z_nr
        );
    }
    if let Some((rms, n)) = summary.eq69_rms_error {
        eprintln!(
            "eq. 69 (Cantor et al. 2020) with this run's phi_0, Z_0: RMS relative error {:.1}% over {n} rows",
            100.0 * rms
        );
    }
    eprintln!(
        "final: phi = {:.4}, p_c = {:.4e}; see {}",
        summary.last.phi,
        summary.last.p_c,
        out_dir.join("macro.csv").display()
    );
    if let Some(m) = &options.mcap {
        let bytes = std::fs::metadata(&m.path).map(|m| m.len()).unwrap_or(0);
        eprintln!(
            "trajectory log: {} ({:.1} MB; {:.2} s writing it, {:.1}% of the run)",
            m.path.display(),
            bytes as f64 / 1e6,
            summary.mcap_seconds,
            100.0 * summary.mcap_seconds / summary.wall_seconds.max(1e-9)
        );
    }
}

/// Ctrl-C / SIGTERM during a checkpointed run: the first stops the run after the current step
/// (a checkpoint is written); a second ends the process at once. Uses the C library's
/// `signal(2)` directly (std links it), so no extra crate.
mod stop_signals {
    use std::sync::atomic::{AtomicBool, Ordering};

    static STOP: AtomicBool = AtomicBool::new(false);

    #[cfg(unix)]
    mod sys {
        unsafe extern "C" {
            pub fn signal(signum: i32, handler: usize) -> usize;
            pub fn _exit(code: i32) -> !;
        }
        pub const SIGINT: i32 = 2;
        pub const SIGTERM: i32 = 15;
    }

    #[cfg(unix)]
    extern "C" fn on_signal(_signum: i32) {
        // Only async-signal-safe work: an atomic swap, and _exit on the second signal.
        if STOP.swap(true, Ordering::SeqCst) {
            unsafe { sys::_exit(130) }
        }
    }

    /// Installs the handlers (once) and returns the flag they set.
    pub fn install() -> &'static AtomicBool {
        #[cfg(unix)]
        {
            static INSTALLED: std::sync::Once = std::sync::Once::new();
            INSTALLED.call_once(|| {
                let handler = on_signal as extern "C" fn(i32) as usize;
                // SAFETY: the handler only touches an atomic and calls _exit.
                unsafe {
                    sys::signal(sys::SIGINT, handler);
                    sys::signal(sys::SIGTERM, handler);
                }
            });
        }
        &STOP
    }
}

/// `sdem inspect`: what a trajectory log holds.
/// `sdem export --vtk`: every frame of the log to VTK files.
fn export_vtk(file: &Path, dir: &Path, outline_nodes: usize, every: usize) -> Result<()> {
    let started = std::time::Instant::now();
    let log = Trajectory::open(file)?;
    let count = log.frame_count();
    if count == 0 {
        bail!("{}: the log holds no frames", file.display());
    }
    let mut writer = VtkWriter::create(dir, VtkOptions { outline_nodes })?;
    for k in (0..count).filter(|k| k % every == 0 || k + 1 == count) {
        let frame = log.frame(k as i64)?;
        writer
            .write_frame(&frame)
            .with_context(|| format!("{}: frame {k}", file.display()))?;
    }
    let summary = writer.finish()?;
    eprintln!(
        "{}: {} frames exported to {} ({:.1} MB, {:.1} s)",
        file.display(),
        summary.frames,
        summary
            .collections
            .iter()
            .map(|p| p.display().to_string())
            .collect::<Vec<_>>()
            .join(", "),
        summary.bytes as f64 / 1e6,
        started.elapsed().as_secs_f64()
    );
    Ok(())
}

fn inspect(file: &Path) -> Result<()> {
    let log = Trajectory::open(file)?;
    let sizes = log.sizes();
    println!(
        "file: {} ({} bytes, written by {})",
        file.display(),
        sizes.file_bytes,
        log.library()
    );
    let meshfree = log.solver() == "meshfree";
    if meshfree {
        println!(
            "solver: meshfree (a meshfree trajectory: each grain's boundary-node contour on {})",
            log.frame_topic()
        );
    }
    if let Some(name) = log.run_info("scenario") {
        if meshfree {
            println!(
                "scenario: {name}, {} grains, dt = {}, boundary nodes = {}",
                log.run_info("grains").unwrap_or("?"),
                log.run_info("dt").unwrap_or("?"),
                log.run_info("boundary_nodes").unwrap_or("?")
            );
        } else {
            println!(
                "scenario: {name}, {} grains, dt = {}, contour nodes = {}",
                log.run_info("grains").unwrap_or("?"),
                log.run_info("dt").unwrap_or("?"),
                log.run_info("contour_nodes").unwrap_or("?")
            );
        }
    }
    let frames = log.frame_count();
    println!("frames: {frames}");
    if let Some(((s0, t0), (s1, t1))) = log.span()? {
        println!("steps: {s0} .. {s1}");
        println!("time span: {t0:.6e} .. {t1:.6e}");
    }
    println!("channels:");
    for c in log.channels() {
        println!(
            "  {:<10} {:>7} messages  {} ({}), {}",
            c.topic, c.messages, c.schema_name, c.schema_encoding, c.message_encoding
        );
    }
    for a in log.attachments() {
        println!(
            "attachment: {} ({}, {} bytes)",
            a.name, a.media_type, a.size
        );
    }
    for (name, values) in log.metadata() {
        let text: Vec<String> = values.iter().map(|(k, v)| format!("{k}={v}")).collect();
        println!("metadata {name}: {}", text.join(", "));
    }
    println!(
        "chunks: {} ({}), {} bytes compressed, {} uncompressed (ratio {:.2})",
        sizes.chunks,
        log.compression(),
        sizes.compressed_bytes,
        sizes.uncompressed_bytes,
        sizes.uncompressed_bytes as f64 / sizes.compressed_bytes.max(1) as f64
    );
    let grains: f64 = log
        .run_info("grains")
        .and_then(|g| g.parse().ok())
        .unwrap_or(0.0);
    if frames > 0 && grains > 0.0 {
        println!(
            "bytes per grain per frame (whole file): {:.1}",
            sizes.file_bytes as f64 / (grains * frames as f64)
        );
    }
    if log.summary_info("status").is_none() {
        println!("note: no sdem.summary metadata (the run did not finish its log)");
    }
    Ok(())
}
