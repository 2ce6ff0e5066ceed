//! The progress bar of a run.

use super::simulation::Simulation;
use crate::boundary::loading::{LoadState, LoadingProgram, StopWhen};
use crate::boundary::walls::box_size;
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use std::time::{Duration, Instant};

/// Fraction of a stop condition reached, when it can be told.
fn stop_fraction(
    until: &StopWhen,
    program: &LoadingProgram,
    sim: &impl Simulation,
    load: &LoadState,
    phi_start: f64,
) -> Option<f64> {
    let (phi, p_c) = (load.phi, load.mean_stress());
    let f = match until {
        StopWhen::PackingFraction(target) => {
            let span = target - phi_start;
            (span.abs() > 1e-12).then(|| (phi - phi_start) / span)?
        }
        StopWhen::MeanStress(target) => (*target > 0.0).then(|| p_c / target)?,
        StopWhen::Jammed => return None,
        StopWhen::Steps(n) => {
            (sim.step_count() - program.phase_start_step) as f64 / (*n).max(1) as f64
        }
        StopWhen::Time(t) => (sim.time() - program.phase_start_time) / t.max(f64::MIN_POSITIVE),
        StopWhen::Strain(e) => {
            let (w0, _) = program.phase_start_size;
            let (w, _) = box_size(sim.walls());
            (1.0 - w / w0) / e
        }
        StopWhen::VerticalStrain(e) => {
            let (_, h0) = program.phase_start_size;
            let (_, h) = box_size(sim.walls());
            (1.0 - h / h0) / e
        }
        StopWhen::ShearStrain(g) => {
            (load.shear_strain - program.phase_start_shear_strain).abs() / g
        }
        StopWhen::Any(list) => {
            return list
                .iter()
                .filter_map(|u| stop_fraction(u, program, sim, load, phi_start))
                .fold(None, |acc: Option<f64>, f| {
                    Some(acc.map_or(f, |a| a.max(f)))
                });
        }
    };
    f.is_finite().then_some(f.clamp(0.0, 1.0))
}

/// The progress bar of a run: appears after [`Progress::DELAY`], redrawn at most 10 times a
/// second, hidden when stderr is not a terminal (indicatif's stderr target).
pub(super) struct Progress {
    enabled: bool,
    bar: Option<ProgressBar>,
    phases: Vec<&'static str>,
    phase_seen: Option<usize>,
    phi_start: f64,
    known: bool,
    last_draw: Option<Instant>,
}

impl Progress {
    const DELAY: Duration = Duration::from_secs(3);
    const PERIOD: Duration = Duration::from_millis(100);

    pub(super) fn new(enabled: bool, phases: &[&'static str]) -> Self {
        Self {
            enabled,
            bar: None,
            phases: phases.to_vec(),
            phase_seen: None,
            phi_start: 0.0,
            known: false,
            last_draw: None,
        }
    }

    fn bar_style() -> ProgressStyle {
        ProgressStyle::with_template(
            "{prefix} [{elapsed_precise}] {bar:30.cyan/blue} {percent:>3}%  {msg}",
        )
        .unwrap_or_else(|_| ProgressStyle::default_bar())
        .progress_chars("=> ")
    }

    fn spinner_style() -> ProgressStyle {
        ProgressStyle::with_template("{prefix} [{elapsed_precise}] {spinner}  {msg}")
            .unwrap_or_else(|_| ProgressStyle::default_spinner())
    }

    pub(super) fn update(
        &mut self,
        program: &LoadingProgram,
        sim: &impl Simulation,
        load: &LoadState,
        started: Instant,
        first_step: u64,
    ) {
        let phi = load.phi;
        if !self.enabled {
            return;
        }
        if self.phase_seen != Some(program.current) {
            self.phase_seen = Some(program.current);
            self.phi_start = phi;
        }
        let now = Instant::now();
        if self.bar.is_none() {
            if now.duration_since(started) < Self::DELAY {
                return;
            }
            let bar = ProgressBar::with_draw_target(Some(1000), ProgressDrawTarget::stderr())
                .with_style(Self::spinner_style());
            bar.set_elapsed(now.duration_since(started));
            self.bar = Some(bar);
        }
        if self
            .last_draw
            .is_some_and(|t| now.duration_since(t) < Self::PERIOD)
        {
            return;
        }
        self.last_draw = Some(now);
        let Some(bar) = &self.bar else { return };
        let fraction = program
            .phase()
            .and_then(|p| stop_fraction(p.until(), program, sim, load, self.phi_start));
        if fraction.is_some() != self.known {
            self.known = fraction.is_some();
            bar.set_style(if self.known {
                Self::bar_style()
            } else {
                Self::spinner_style()
            });
        }
        bar.set_prefix(format!(
            "{} {}/{}",
            program.phase().map_or("end", |p| p.name()),
            (program.current + 1).min(self.phases.len()),
            self.phases.len()
        ));
        if let Some(f) = fraction {
            bar.set_position((f * 1000.0) as u64);
        } else {
            bar.tick();
        }
        let elapsed = now.duration_since(started).as_secs_f64().max(1e-9);
        bar.set_message(format!(
            "step {}  φ {:.4}  p_c {:.3e}  contacts {}  {:.2e} grain-steps/s",
            sim.step_count(),
            phi,
            load.mean_stress(),
            sim.contacts(),
            (sim.step_count() - first_step) as f64 * sim.grain_count() as f64 / elapsed
        ));
    }

    pub(super) fn suspend<R>(&self, f: impl FnOnce() -> R) -> R {
        match &self.bar {
            Some(bar) => bar.suspend(f),
            None => f(),
        }
    }

    pub(super) fn finish(&mut self) {
        if let Some(bar) = self.bar.take() {
            bar.finish_and_clear();
        }
    }
}
