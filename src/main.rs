//! The `sdem` command line (SPEC §12).

use anyhow::{Context, Result, bail};
use clap::{Parser, Subcommand};
use sdem::run::{RunOptions, run_scenario};
use sdem::scenario::Scenario;
use std::io::IsTerminal;
use std::path::PathBuf;

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
    },
    /// Time the SDEM step on a dense packing (phi ~ 0.9, nu = 0.5, dbeta = 1 degree).
    Bench {
        /// Number of grains (rounded up to full lattice rows).
        #[arg(long, default_value_t = 10_000)]
        grains: usize,
        /// Timed steps (after 20 warm-up steps).
        #[arg(long, default_value_t = 200)]
        steps: u64,
        #[arg(long)]
        threads: Option<usize>,
        /// Contour resolution dbeta in degrees.
        #[arg(long, default_value_t = 1.0)]
        resolution: f64,
    },
    /// Check a scenario file and print its warnings and derived settings, without running it.
    Check { scenario: PathBuf },
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
    match cli.command {
        Command::Run {
            scenario,
            out,
            threads,
            quiet,
        } => {
            let parsed = load(&scenario)?;
            let out_dir = out.unwrap_or_else(|| PathBuf::from("out").join(&parsed.name));
            let pool = thread_pool(threads)?;
            eprintln!(
                "sdem: {} — {} grains, dt = {:.3e} ({:.2} x critical), {} threads, output in {}",
                parsed.name,
                parsed.sample.count,
                parsed.time_step_value(),
                parsed.time_step_value() / parsed.critical_time_step(),
                pool.current_num_threads(),
                out_dir.display()
            );
            let options = RunOptions {
                out_dir: out_dir.clone(),
                progress_seconds: (!quiet).then_some(if std::io::stderr().is_terminal() {
                    2.0
                } else {
                    30.0
                }),
            };
            let summary = pool.install(|| run_scenario(&parsed, &options))?;
            eprintln!(
                "done: {} steps in {:.1} s ({:.3e} grain-steps/s)",
                summary.steps,
                summary.wall_seconds,
                summary.steps as f64 * summary.grains as f64 / summary.wall_seconds.max(1e-9)
            );
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
        }
        Command::Bench {
            grains,
            steps,
            threads,
            resolution,
        } => {
            if grains < 4 || steps == 0 {
                bail!("--grains must be at least 4 and --steps at least 1");
            }
            let pool = thread_pool(threads)?;
            let result = pool.install(|| {
                let mut world = sdem::run::bench::dense_packing(grains, resolution);
                sdem::run::bench::run_bench(&mut world, 20, steps)
            })?;
            println!(
                "grains: {}  steps: {}  threads: {}  phi: {:.3}  contacts per grain: {:.2}  seconds: {:.3}",
                result.grains,
                result.steps,
                pool.current_num_threads(),
                result.phi,
                2.0 * result.contacts as f64 / result.grains as f64,
                result.seconds
            );
            println!("grain-steps/s: {:.4e}", result.grain_steps_per_second());
        }
        Command::Check { scenario } => {
            let parsed = load(&scenario)?;
            println!("{}: valid", scenario.display());
            println!(
                "critical time step estimate: {:.4e}",
                parsed.critical_time_step()
            );
            println!("time step: {:.4e}", parsed.time_step_value());
        }
    }
    Ok(())
}
