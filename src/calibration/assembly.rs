//! `sdem calibrate --assembly`: fits the secant law's (a, b) to grain-resolved reference runs of
//! whole assemblies (docs/sdem_vs_meshfree.md), where `sdem calibrate` fits it to one disc.
//!
//! Each case is an SDEM scenario and a reference run of the same packing, walls, loading and
//! material (e.g. a meshfree run written by `tools/sdem_vs_meshfree.py`). For each (a, b) the
//! scenarios are run with that law, and the error of a case is the relative error of SDEM's
//! mean wall stress `p_c` against the reference's, at the same volumetric strain of the box, over
//! the loaded part of the reference (`p_c >= loaded_pressure E`). The pooled error of a pair is
//! the RMS over the points of every case: one pair for all the loadings given.
//!
//! The search: the grid `a_values x b_values`, then Nelder–Mead from the grid's best pair, for
//! `refine_evaluations` more runs of the cases at most. The scenarios' own laws are evaluated
//! too, to say what the fitted pair gains.
//!
//! Volumetric strain: `1 - A / A0`, with `A` the box area of a row and `A0` the scenario's
//! initial box area (the reference starts from the same box); compression positive.

use std::fmt;
use std::path::PathBuf;
use std::sync::atomic::{AtomicUsize, Ordering};

use rayon::prelude::*;

use super::CalibrationError;
use crate::output::measures::Measures;
use crate::output::plot::read_macro_csv;
use crate::run::{RunOptions, run_scenario};
use crate::scenario::Scenario;

/// The default grid of `a` (the paper's 0.58 among them).
pub const DEFAULT_A: [f64; 8] = [0.45, 0.5, 0.58, 0.65, 0.75, 0.85, 1.0, 1.2];
/// The default grid of `b` (the paper's 2 among them; the law needs b > 0).
pub const DEFAULT_B: [f64; 6] = [0.5, 1.0, 1.5, 2.0, 3.0, 4.0];

/// One loading to fit: an SDEM scenario and the reference run of the same packing and walls.
#[derive(Debug, Clone)]
pub struct AssemblyCase {
    /// Names the case in tables and run directories (e.g. the scenario file's stem).
    pub label: String,
    pub scenario: Scenario,
    /// The reference's `macro.csv` rows (`box_width`, `box_height` and `p_c` are used).
    pub reference: Vec<Measures>,
}

impl AssemblyCase {
    /// Reads the reference `macro.csv` (or the run directory holding it).
    pub fn new(
        label: &str,
        scenario: Scenario,
        reference: &std::path::Path,
    ) -> Result<Self, CalibrationError> {
        let csv = if reference.is_dir() {
            reference.join("macro.csv")
        } else {
            reference.to_path_buf()
        };
        let rows = read_macro_csv(&csv).map_err(CalibrationError::BadInput)?;
        Ok(Self {
            label: label.to_string(),
            scenario,
            reference: rows,
        })
    }

    fn initial_area(&self) -> f64 {
        self.scenario.sample.box_width * self.scenario.sample.box_height
    }

    fn loaded_pressure(&self, options: &AssemblyOptions) -> f64 {
        options.loaded_pressure * self.scenario.material.young
    }
}

/// Options of the assembly calibration.
#[derive(Debug, Clone)]
pub struct AssemblyOptions {
    pub cases: Vec<AssemblyCase>,
    pub a_values: Vec<f64>,
    pub b_values: Vec<f64>,
    /// Nelder–Mead evaluations after the grid (0: the grid only).
    pub refine_evaluations: usize,
    /// Where `assembly_fit.csv`, `assembly_fit.txt` and the runs (`runs/<case>_a<a>_b<b>/`) go.
    pub out_dir: PathBuf,
    /// The loaded part: reference rows with `p_c` at or above this many E.
    pub loaded_pressure: f64,
    /// Strain between two compared points.
    pub strain_step: f64,
}

impl AssemblyOptions {
    pub fn new(cases: Vec<AssemblyCase>, out_dir: PathBuf) -> Self {
        Self {
            cases,
            a_values: DEFAULT_A.to_vec(),
            b_values: DEFAULT_B.to_vec(),
            refine_evaluations: 20,
            out_dir,
            loaded_pressure: 5e-3,
            strain_step: 2.5e-3,
        }
    }
}

/// The error of one run against its reference.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CaseError {
    /// RMS relative error of p_c over the loaded points.
    pub rms: f64,
    /// Largest |relative error| of p_c over them.
    pub max: f64,
    /// Relative error of p_c at the last loaded point (signed: positive when SDEM is stiffer).
    pub end: f64,
    /// Sum of the squared relative errors (for the pooled RMS) and the number of points.
    pub sum_squares: f64,
    pub points: usize,
}

/// Where an evaluated pair comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Stage {
    /// A scenario's own contact law.
    Scenario,
    Grid,
    Refine,
}

impl Stage {
    fn name(self) -> &'static str {
        match self {
            Stage::Scenario => "scenario",
            Stage::Grid => "grid",
            Stage::Refine => "refine",
        }
    }
}

/// One (a, b) run on every case.
#[derive(Debug, Clone)]
pub struct Evaluation {
    pub stage: Stage,
    pub a: f64,
    pub b: f64,
    /// Per case, in the order of the options; `Err` holds why the run failed.
    pub cases: Vec<Result<CaseError, String>>,
}

impl Evaluation {
    /// RMS over the points of all cases; infinite if a case failed or has no point.
    pub fn pooled_rms(&self) -> f64 {
        let mut sum = 0.0;
        let mut points = 0;
        for c in &self.cases {
            match c {
                Ok(e) if e.points > 0 => {
                    sum += e.sum_squares;
                    points += e.points;
                }
                _ => return f64::INFINITY,
            }
        }
        (sum / points as f64).sqrt()
    }

    fn case_rms(&self, k: usize) -> f64 {
        match &self.cases[k] {
            Ok(e) if e.points > 0 => e.rms,
            _ => f64::INFINITY,
        }
    }
}

/// Everything evaluated, and the best pairs.
#[derive(Debug, Clone)]
pub struct AssemblyReport {
    pub labels: Vec<String>,
    /// The (a, b) of the scenarios, each once.
    pub scenario_laws: Vec<(f64, f64)>,
    pub loaded_pressure: f64,
    pub evaluations: Vec<Evaluation>,
}

impl AssemblyReport {
    fn best_by(&self, score: impl Fn(&Evaluation) -> f64, stages: &[Stage]) -> Option<&Evaluation> {
        self.evaluations
            .iter()
            .filter(|e| stages.contains(&e.stage) && score(e).is_finite())
            .min_by(|x, y| score(x).total_cmp(&score(y)))
    }

    /// The pair with the lowest pooled error (grid and refinement).
    pub fn best(&self) -> Option<&Evaluation> {
        self.best_by(Evaluation::pooled_rms, &[Stage::Grid, Stage::Refine])
    }

    /// The best pair of the grid alone.
    pub fn best_of_grid(&self) -> Option<&Evaluation> {
        self.best_by(Evaluation::pooled_rms, &[Stage::Grid])
    }

    /// The pair that fits case `k` best on its own.
    pub fn best_for_case(&self, k: usize) -> Option<&Evaluation> {
        self.best_by(|e| e.case_rms(k), &[Stage::Grid, Stage::Refine])
    }

    fn describe(&self, e: &Evaluation) -> String {
        let per_case: Vec<String> = self
            .labels
            .iter()
            .zip(&e.cases)
            .map(|(label, c)| match c {
                Ok(c) => format!(
                    "{label} {:.1}% (largest {:.1}%, {:+.1}% at the end)",
                    100.0 * c.rms,
                    100.0 * c.max,
                    100.0 * c.end
                ),
                Err(why) => format!("{label} failed: {why}"),
            })
            .collect();
        format!(
            "a = {}, b = {}: pooled RMS {:.1}% ({})",
            e.a,
            e.b,
            100.0 * e.pooled_rms(),
            per_case.join("; ")
        )
    }
}

impl fmt::Display for AssemblyReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(
            f,
            "assembly calibration of the secant law: relative error of p_c against {} reference run(s) \
             over their loaded part (p_c >= {:e} E), {} evaluations",
            self.labels.len(),
            self.loaded_pressure,
            self.evaluations.len()
        )?;
        for &(a, b) in &self.scenario_laws {
            if let Some(e) = self.evaluations.iter().find(|e| (e.a, e.b) == (a, b)) {
                writeln!(f, "  the scenario's law, {}", self.describe(e))?;
            }
        }
        if let Some(e) = self.best_of_grid() {
            let grid = self
                .evaluations
                .iter()
                .filter(|e| e.stage == Stage::Grid)
                .count();
            writeln!(f, "  best of the grid ({grid} pairs), {}", self.describe(e))?;
        }
        if let Some(e) = self.best() {
            writeln!(f, "  best, {}", self.describe(e))?;
        }
        if self.labels.len() > 1 {
            for (k, label) in self.labels.iter().enumerate() {
                if let Some(e) = self.best_for_case(k) {
                    writeln!(
                        f,
                        "  best for {label} alone: a = {}, b = {}: {:.1}%",
                        e.a,
                        e.b,
                        100.0 * e.case_rms(k)
                    )?;
                }
            }
        }
        if let Some(e) = self.best() {
            writeln!(f, "a = {}", e.a)?;
            write!(f, "b = {}", e.b)?;
        }
        Ok(())
    }
}

/// The volumetric strain `1 - A / A0` and `p_c` of each row.
pub fn strain_curve(rows: &[Measures], initial_area: f64) -> Vec<(f64, f64)> {
    rows.iter()
        .map(|r| (1.0 - r.box_width * r.box_height / initial_area, r.p_c))
        .collect()
}

/// The value of a (strain, value) curve at `strain`, interpolated linearly in the first row
/// interval that holds it; `None` outside the curve.
pub fn value_at(curve: &[(f64, f64)], strain: f64) -> Option<f64> {
    curve.windows(2).find_map(|w| {
        let ((x0, y0), (x1, y1)) = (w[0], w[1]);
        (x0 <= strain && strain <= x1 && x1 > x0)
            .then(|| y0 + (strain - x0) / (x1 - x0) * (y1 - y0))
    })
}

/// The relative error of `run`'s p_c against `reference`'s at the strains `k strain_step` they
/// share, where the reference's p_c is at least `loaded_pressure`.
pub fn p_error(
    reference: &[(f64, f64)],
    run: &[(f64, f64)],
    strain_step: f64,
    loaded_pressure: f64,
) -> CaseError {
    let end = |c: &[(f64, f64)]| c.iter().map(|p| p.0).fold(f64::NEG_INFINITY, f64::max);
    let last = end(reference).min(end(run));
    let (mut sum_squares, mut max, mut at_end, mut points) = (0.0, 0.0f64, f64::NAN, 0);
    let mut k = 1;
    while k as f64 * strain_step <= last {
        let strain = k as f64 * strain_step;
        k += 1;
        let (Some(r), Some(v)) = (value_at(reference, strain), value_at(run, strain)) else {
            continue;
        };
        if r < loaded_pressure {
            continue;
        }
        let err = (v - r) / r;
        sum_squares += err * err;
        max = max.max(err.abs());
        at_end = err;
        points += 1;
    }
    CaseError {
        rms: if points > 0 {
            (sum_squares / points as f64).sqrt()
        } else {
            f64::NAN
        },
        max,
        end: at_end,
        sum_squares,
        points,
    }
}

fn check(options: &AssemblyOptions) -> Result<(), CalibrationError> {
    let bad = |m: String| Err(CalibrationError::BadInput(m));
    if options.cases.is_empty() {
        return bad("no assembly to fit: give a scenario and its reference run".into());
    }
    for (name, values) in [("a", &options.a_values), ("b", &options.b_values)] {
        if values.is_empty() {
            return bad(format!("the grid of {name} is empty"));
        }
        if let Some(v) = values.iter().find(|v| !(v.is_finite() && **v > 0.0)) {
            return bad(format!(
                "{name} = {v} in the grid: the secant law needs a > 0 and b > 0"
            ));
        }
    }
    if !(options.strain_step > 0.0 && options.loaded_pressure > 0.0) {
        return bad("the strain step and the loaded pressure must be > 0".into());
    }
    for (k, case) in options.cases.iter().enumerate() {
        let label = &case.label;
        if options.cases[..k].iter().any(|c| c.label == *label) {
            return bad(format!(
                "two cases are labelled {label}: each needs its own label (it names its run directories)"
            ));
        }
        if crate::run::meshfree::settings_of(&case.scenario).is_some() {
            return bad(format!(
                "{label}: a meshfree scenario; the assembly calibration runs SDEM scenarios against a reference run"
            ));
        }
        let area0 = case.initial_area();
        let curve = strain_curve(&case.reference, area0);
        let Some(&(first, _)) = curve.first() else {
            return bad(format!("{label}: the reference run has no rows"));
        };
        if !(-1e-9..=0.05).contains(&first) {
            return bad(format!(
                "{label}: the reference's first row has a box of area {:.6e}, a strain of {first:.4} \
                 from the scenario's box ({area0:.6e}): the reference must start from the scenario's \
                 box (strain between 0 and 0.05)",
                area0 * (1.0 - first)
            ));
        }
        let threshold = case.loaded_pressure(options);
        if !case.reference.iter().any(|r| r.p_c >= threshold) {
            return bad(format!(
                "{label}: the reference's p_c never reaches {threshold:e} (the loaded part): nothing to fit"
            ));
        }
    }
    Ok(())
}

/// Runs `case` with the law (a, b) in `out_dir/runs/` and measures it.
fn run_case(
    case: &AssemblyCase,
    a: f64,
    b: f64,
    options: &AssemblyOptions,
) -> Result<CaseError, String> {
    let mut scenario = case.scenario.clone();
    scenario.contact.a = a;
    scenario.contact.b = b;
    scenario.validate().map_err(|e| e.to_string())?;
    let out_dir = options
        .out_dir
        .join("runs")
        .join(format!("{}_a{a}_b{b}", case.label));
    let run_options = RunOptions {
        out_dir: out_dir.clone(),
        ..Default::default()
    };
    run_scenario(&scenario, &run_options).map_err(|e| e.to_string())?;
    let rows = read_macro_csv(&out_dir.join("macro.csv"))?;
    let area0 = case.initial_area();
    Ok(p_error(
        &strain_curve(&case.reference, area0),
        &strain_curve(&rows, area0),
        options.strain_step,
        case.loaded_pressure(options),
    ))
}

/// Rounds a trial value to 4 decimals: readable run names, and the same point never run twice.
fn round4(x: f64) -> f64 {
    (x * 1e4).round() / 1e4
}

struct Evaluator<'a> {
    options: &'a AssemblyOptions,
    done: AtomicUsize,
    total: usize,
}

impl Evaluator<'_> {
    fn evaluate(&self, stage: Stage, a: f64, b: f64) -> Evaluation {
        let cases = self
            .options
            .cases
            .par_iter()
            .map(|case| run_case(case, a, b, self.options))
            .collect();
        let e = Evaluation { stage, a, b, cases };
        let n = self.done.fetch_add(1, Ordering::Relaxed) + 1;
        eprintln!(
            "calibrate --assembly: [{n}/{}] {} a = {a}, b = {b}: pooled RMS {:.1}%",
            self.total,
            stage.name(),
            100.0 * e.pooled_rms()
        );
        e
    }
}

/// Nelder–Mead on the pooled error from `start`, `budget` evaluations at most; trial points
/// with a or b <= 0 score infinity without a run.
fn refine(
    evaluator: &Evaluator,
    evaluations: &mut Vec<Evaluation>,
    start: (f64, f64),
    step: (f64, f64),
    budget: usize,
) {
    let mut used = 0;
    let mut score = |p: (f64, f64), evaluations: &mut Vec<Evaluation>| -> f64 {
        let (a, b) = (round4(p.0), round4(p.1));
        if a <= 0.0 || b <= 0.0 {
            return f64::INFINITY;
        }
        if let Some(e) = evaluations.iter().find(|e| e.a == a && e.b == b) {
            return e.pooled_rms();
        }
        if used >= budget {
            return f64::NAN;
        }
        used += 1;
        let e = evaluator.evaluate(Stage::Refine, a, b);
        let s = e.pooled_rms();
        evaluations.push(e);
        s
    };
    let mut simplex: Vec<((f64, f64), f64)> = [
        start,
        (start.0 + step.0, start.1),
        (start.0, start.1 + step.1),
    ]
    .into_iter()
    .map(|p| (p, score(p, evaluations)))
    .collect();
    let lerp =
        |p: (f64, f64), q: (f64, f64), t: f64| (p.0 + t * (q.0 - p.0), p.1 + t * (q.1 - p.1));
    loop {
        if simplex.iter().any(|s| s.1.is_nan()) {
            return; // the budget is spent
        }
        simplex.sort_by(|x, y| x.1.total_cmp(&y.1));
        let size = simplex
            .iter()
            .map(|s| {
                (s.0.0 - simplex[0].0.0)
                    .abs()
                    .max((s.0.1 - simplex[0].0.1).abs())
            })
            .fold(0.0, f64::max);
        if size < 2e-4 {
            return; // below the rounding of the trial points
        }
        let centroid = lerp(simplex[0].0, simplex[1].0, 0.5);
        let worst = simplex[2];
        let reflected = lerp(worst.0, centroid, 2.0);
        let fr = score(reflected, evaluations);
        if fr.is_nan() {
            return;
        }
        if fr < simplex[0].1 {
            let expanded = lerp(worst.0, centroid, 3.0);
            let fe = score(expanded, evaluations);
            simplex[2] = if fe < fr {
                (expanded, fe)
            } else {
                (reflected, fr)
            };
        } else if fr < simplex[1].1 {
            simplex[2] = (reflected, fr);
        } else {
            let contracted = if fr < worst.1 {
                lerp(worst.0, centroid, 1.5)
            } else {
                lerp(worst.0, centroid, 0.5)
            };
            let fc = score(contracted, evaluations);
            if fc < worst.1.min(fr) {
                simplex[2] = (contracted, fc);
            } else {
                let best = simplex[0].0;
                for s in simplex.iter_mut().skip(1) {
                    let p = lerp(best, s.0, 0.5);
                    *s = (p, score(p, evaluations));
                }
            }
        }
    }
}

/// Half the distance from `x` to its nearest neighbour in `grid` (10% of `x` without one): the
/// first simplex of the refinement.
fn local_step(grid: &[f64], x: f64) -> f64 {
    let nearest = grid
        .iter()
        .filter(|&&g| g != x)
        .map(|g| (g - x).abs())
        .fold(f64::INFINITY, f64::min);
    if nearest.is_finite() {
        0.5 * nearest
    } else {
        0.1 * x
    }
}

/// Runs the calibration: the scenarios' own laws, the grid, the refinement; writes
/// `assembly_fit.csv` (one row per evaluation and case) and `assembly_fit.txt` (the report).
pub fn run_assembly_calibration(
    options: &AssemblyOptions,
) -> Result<AssemblyReport, CalibrationError> {
    check(options)?;
    std::fs::create_dir_all(&options.out_dir).map_err(CalibrationError::io(&options.out_dir))?;

    let mut own: Vec<(f64, f64)> = Vec::new();
    for case in &options.cases {
        let pair = (case.scenario.contact.a, case.scenario.contact.b);
        if !own.contains(&pair) {
            own.push(pair);
        }
    }
    let grid: Vec<(f64, f64)> = options
        .a_values
        .iter()
        .flat_map(|&a| options.b_values.iter().map(move |&b| (a, b)))
        .collect();
    let evaluator = Evaluator {
        options,
        done: AtomicUsize::new(0),
        total: own.iter().filter(|p| !grid.contains(p)).count()
            + grid.len()
            + options.refine_evaluations,
    };
    // A scenario's law on the grid is run once, as a grid point.
    let jobs: Vec<(Stage, (f64, f64))> = own
        .iter()
        .filter(|p| !grid.contains(p))
        .map(|&p| (Stage::Scenario, p))
        .chain(grid.iter().map(|&p| (Stage::Grid, p)))
        .collect();
    let mut report = AssemblyReport {
        labels: options.cases.iter().map(|c| c.label.clone()).collect(),
        scenario_laws: own,
        loaded_pressure: options.loaded_pressure,
        evaluations: jobs
            .par_iter()
            .map(|&(stage, (a, b))| evaluator.evaluate(stage, a, b))
            .collect(),
    };
    let Some(start) = report.best_of_grid().map(|e| (e.a, e.b)) else {
        let why = report
            .evaluations
            .iter()
            .flat_map(|e| e.cases.iter())
            .find_map(|c| c.as_ref().err().cloned())
            .unwrap_or_else(|| "no loaded point in common with the reference".into());
        return Err(CalibrationError::Fit(format!(
            "no pair of the grid ran every case to a loaded point; the first failure: {why}"
        )));
    };
    if options.refine_evaluations > 0 {
        let step = (
            local_step(&options.a_values, start.0),
            local_step(&options.b_values, start.1),
        );
        refine(
            &evaluator,
            &mut report.evaluations,
            start,
            step,
            options.refine_evaluations,
        );
    }
    write_outputs(&report, options)?;
    Ok(report)
}

fn write_outputs(
    report: &AssemblyReport,
    options: &AssemblyOptions,
) -> Result<(), CalibrationError> {
    use std::fmt::Write;
    let mut csv = String::from(
        "stage,a,b,case,rms_rel_err_p,max_rel_err_p,rel_err_p_end,points,pooled_rms_rel_err_p,failure\n",
    );
    for e in &report.evaluations {
        for (label, c) in report.labels.iter().zip(&e.cases) {
            let _ = match c {
                Ok(c) => writeln!(
                    csv,
                    "{},{},{},{label},{:.6e},{:.6e},{:.6e},{},{:.6e},",
                    e.stage.name(),
                    e.a,
                    e.b,
                    c.rms,
                    c.max,
                    c.end,
                    c.points,
                    e.pooled_rms()
                ),
                Err(why) => writeln!(
                    csv,
                    "{},{},{},{label},nan,nan,nan,0,inf,\"{}\"",
                    e.stage.name(),
                    e.a,
                    e.b,
                    why.replace('"', "'")
                ),
            };
        }
    }
    let path = options.out_dir.join("assembly_fit.csv");
    std::fs::write(&path, csv).map_err(CalibrationError::io(&path))?;
    let path = options.out_dir.join("assembly_fit.txt");
    std::fs::write(&path, format!("{report}\n")).map_err(CalibrationError::io(&path))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn interpolates_inside_the_curve_only() {
        let curve = [(0.0, 0.0), (0.1, 1.0), (0.3, 2.0)];
        assert_eq!(value_at(&curve, 0.05), Some(0.5));
        assert_eq!(value_at(&curve, 0.2), Some(1.5));
        assert_eq!(value_at(&curve, 0.31), None);
    }

    #[test]
    fn a_run_scaled_by_a_factor_has_that_relative_error() {
        // Expectation: p_run = 1.1 p_ref at every strain gives 10% everywhere, whatever the
        // row spacing of either curve; points below the loaded pressure are left out.
        let reference: Vec<(f64, f64)> = (0..=200)
            .map(|k| (k as f64 * 5e-4, k as f64 * 1e-3))
            .collect();
        let run: Vec<(f64, f64)> = (0..=37)
            .map(|k| (k as f64 * 2.7e-3, 1.1 * k as f64 * 2.7e-3 / 5e-4 * 1e-3))
            .collect();
        let e = p_error(&reference, &run, 2.5e-3, 5e-3);
        assert!(
            (e.rms - 0.1).abs() < 1e-9 && (e.max - 0.1).abs() < 1e-9 && (e.end - 0.1).abs() < 1e-9,
            "{e:?}"
        );
        // The curves share strains up to 0.0999 (the run's end); loaded from strain 0.0025.
        assert_eq!(e.points, 39);
        let same = p_error(&reference, &reference, 2.5e-3, 5e-3);
        assert_eq!((same.rms, same.max), (0.0, 0.0));
    }

    #[test]
    fn the_pooled_error_weighs_every_point_once() {
        let case = |rms: f64, points: usize| {
            Ok(CaseError {
                rms,
                max: rms,
                end: rms,
                sum_squares: rms * rms * points as f64,
                points,
            })
        };
        let e = Evaluation {
            stage: Stage::Grid,
            a: 1.0,
            b: 2.0,
            cases: vec![case(0.1, 30), case(0.2, 10)],
        };
        assert!((e.pooled_rms() - ((0.01 * 30.0 + 0.04 * 10.0) / 40.0f64).sqrt()).abs() < 1e-15);
        let failed = Evaluation {
            cases: vec![case(0.1, 30), Err("x".into())],
            ..e
        };
        assert!(failed.pooled_rms().is_infinite());
    }
}
