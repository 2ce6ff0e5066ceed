//! Plots of the macroscopic curves (`sdem plot`): p_c against phi with the eq. 69 reference,
//! the coordination number against p_c, and q_c against p_c; PNG or SVG, from `macro.csv` (with
//! the jamming point of the `summary.txt` beside it) or from a trajectory log.

use crate::output::mcap::Trajectory;
use crate::output::measures::Measures;
use crate::output::reference::CantorReference;
use crate::output::render::{FONT_FAMILY, register_fonts};
use plotters::coord::Shift;
use plotters::prelude::*;
use std::path::{Path, PathBuf};

/// The rows of a run and what the plots need besides them.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct MacroSeries {
    /// Scenario name (for captions), if known.
    pub name: String,
    pub rows: Vec<Measures>,
    /// Jamming point (phi_0, Z_0) for eq. 69: from `summary.txt` / the log's `sdem.summary`
    /// (`phi_0`, `z_nr_0`), else the first row with p_c above `1e-5 E`.
    pub jamming: Option<(f64, f64)>,
    /// Young's modulus: stresses are plotted as p_c / E.
    pub young: f64,
    /// Whether the grains are incompressible (eq. 69 holds for nu = 0.5 only); `None`: unknown.
    pub incompressible: Option<bool>,
}

/// Output format of the plots.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PlotFormat {
    Png,
    Svg,
}

impl PlotFormat {
    pub fn extension(self) -> &'static str {
        match self {
            PlotFormat::Png => "png",
            PlotFormat::Svg => "svg",
        }
    }
}

/// Parses `macro.csv` (columns found by name; `step`, `phi`, `p_c` required).
pub fn read_macro_csv(path: &Path) -> Result<Vec<Measures>, String> {
    let text =
        std::fs::read_to_string(path).map_err(|e| format!("reading {}: {e}", path.display()))?;
    let mut lines = text.lines();
    let header: Vec<&str> = lines
        .next()
        .ok_or_else(|| format!("{}: empty file", path.display()))?
        .split(',')
        .map(str::trim)
        .collect();
    let col = |name: &str| header.iter().position(|c| *c == name);
    for required in ["step", "phi", "p_c"] {
        if col(required).is_none() {
            return Err(format!(
                "{}: no column `{required}` in its header",
                path.display()
            ));
        }
    }
    let mut rows = Vec::new();
    for (k, line) in lines.enumerate() {
        if line.trim().is_empty() {
            continue;
        }
        let fields: Vec<&str> = line.split(',').collect();
        let bad = |name: &str| format!("{}:{}: bad value in `{name}`", path.display(), k + 2);
        let float = |name: &str| -> Result<f64, String> {
            match col(name) {
                None => Ok(0.0),
                Some(c) => fields
                    .get(c)
                    .and_then(|v| v.trim().parse::<f64>().ok())
                    .ok_or_else(|| bad(name)),
            }
        };
        let int = |name: &str| -> Result<u64, String> {
            match col(name) {
                None => Ok(0),
                Some(c) => fields
                    .get(c)
                    .and_then(|v| v.trim().parse::<u64>().ok())
                    .ok_or_else(|| bad(name)),
            }
        };
        rows.push(Measures {
            step: int("step")?,
            time: float("time")?,
            phase: col("phase")
                .and_then(|c| fields.get(c))
                .map(|s| s.trim().to_string())
                .unwrap_or_default(),
            phi: float("phi")?,
            sxx_c: float("sxx_c")?,
            syy_c: float("syy_c")?,
            p_c: float("p_c")?,
            q_c: float("q_c")?,
            z: float("z")?,
            z_nr: float("z_nr")?,
            z_nr3: float("z_nr3")?,
            kinetic_energy: float("kinetic_energy")?,
            elastic_energy: float("elastic_energy")?,
            inertial_number: float("inertial_number")?,
            strain_rate: float("strain_rate")?,
            box_width: float("box_width")?,
            box_height: float("box_height")?,
            contacts: int("contacts")?,
            capped_contacts: int("capped_contacts")?,
            levels: [
                int("grains_rigid")?,
                int("grains_volumetric")?,
                int("grains_full")?,
            ],
        });
    }
    Ok(rows)
}

/// `key = value` lines of a `summary.txt`.
fn read_key_values(path: &Path) -> Option<Vec<(String, String)>> {
    let text = std::fs::read_to_string(path).ok()?;
    Some(
        text.lines()
            .filter_map(|l| l.split_once('='))
            .map(|(k, v)| (k.trim().to_string(), v.trim().to_string()))
            .collect(),
    )
}

/// First row with p_c above `1e-5 E`, as a fallback jamming point (phi, z_nr).
fn detect_jamming(rows: &[Measures], young: f64) -> Option<(f64, f64)> {
    rows.iter()
        .find(|r| r.p_c > 1e-5 * young)
        .map(|r| (r.phi, r.z_nr))
}

impl MacroSeries {
    /// From a run directory, a `macro.csv`, or a trajectory log (`.mcap`).
    pub fn load(source: &Path) -> Result<Self, String> {
        let is_mcap = source
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("mcap"));
        if is_mcap {
            let log = Trajectory::open(source).map_err(|e| e.to_string())?;
            return Self::from_trajectory(&log).map_err(|e| e.to_string());
        }
        let csv = if source.is_dir() {
            source.join("macro.csv")
        } else {
            source.to_path_buf()
        };
        let rows = read_macro_csv(&csv)?;
        let young = 1.0;
        let summary = csv
            .parent()
            .and_then(|d| read_key_values(&d.join("summary.txt")))
            .unwrap_or_default();
        let get = |k: &str| {
            summary
                .iter()
                .find(|(key, _)| key == k)
                .and_then(|(_, v)| v.parse::<f64>().ok())
        };
        let name = summary
            .iter()
            .find(|(k, _)| k == "scenario")
            .map(|(_, v)| v.clone())
            .unwrap_or_default();
        let jamming = match (get("phi_0"), get("z_nr_0")) {
            (Some(phi), Some(z)) => Some((phi, z)),
            _ => detect_jamming(&rows, young),
        };
        let incompressible = get("eq69_points").map(|_| true);
        Ok(Self {
            name,
            rows,
            jamming,
            young,
            incompressible,
        })
    }

    pub fn from_trajectory(log: &Trajectory) -> Result<Self, crate::output::mcap::ReadError> {
        let rows = log.macro_rows()?;
        let number = |v: Option<&str>| v.and_then(|s| s.parse::<f64>().ok());
        let young = number(log.run_info("young")).unwrap_or(1.0);
        let jamming = match (
            number(log.summary_info("phi_0")),
            number(log.summary_info("z_nr_0")),
        ) {
            (Some(phi), Some(z)) => Some((phi, z)),
            _ => detect_jamming(&rows, young),
        };
        Ok(Self {
            name: log.run_info("scenario").unwrap_or_default().to_string(),
            rows,
            jamming,
            young,
            incompressible: number(log.run_info("poisson")).map(|nu| nu == 0.5),
        })
    }
}

fn err<E: std::fmt::Display>(e: E) -> String {
    e.to_string()
}

/// Tick label in scientific notation, with "0" for values that are zero to within `span`.
fn tick(v: f64, span: f64) -> String {
    if v.abs() <= 1e-9 * span.abs() {
        "0".to_string()
    } else {
        format!("{v:.1e}")
    }
}

/// The rows from the jamming point on (all rows with p_c > 0 if it is unknown): the loaded
/// sample, where coordination numbers and stress ratios mean something.
fn loaded_rows(s: &MacroSeries) -> Vec<&Measures> {
    let phi0 = s.jamming.map_or(f64::NEG_INFINITY, |j| j.0);
    s.rows
        .iter()
        .filter(|r| r.phi >= phi0 - 1e-12 && r.p_c > 0.0 && r.p_c.is_finite())
        .collect()
}

const WIDTH: u32 = 900;
const HEIGHT: u32 = 650;

fn font(size: u32) -> TextStyle<'static> {
    (FONT_FAMILY, size).into_font().into()
}

/// Writes `p_phi`, `z_p` and `q_p` plots into `out_dir`; returns their paths.
pub fn plot_macro(
    series: &MacroSeries,
    out_dir: &Path,
    format: PlotFormat,
) -> Result<Vec<PathBuf>, String> {
    register_fonts();
    if series.rows.is_empty() {
        return Err("no macroscopic rows to plot".into());
    }
    std::fs::create_dir_all(out_dir).map_err(|e| format!("{}: {e}", out_dir.display()))?;
    let mut written = Vec::new();
    for name in ["p_phi", "z_p", "q_p"] {
        let path = out_dir.join(format!("{name}.{}", format.extension()));
        match format {
            PlotFormat::Png => {
                let root = BitMapBackend::new(&path, (WIDTH, HEIGHT)).into_drawing_area();
                draw_named(&root, name, series)?;
                root.present().map_err(err)?;
            }
            PlotFormat::Svg => {
                let root = SVGBackend::new(&path, (WIDTH, HEIGHT)).into_drawing_area();
                draw_named(&root, name, series)?;
                root.present().map_err(err)?;
            }
        }
        written.push(path);
    }
    Ok(written)
}

fn draw_named<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    name: &str,
    series: &MacroSeries,
) -> Result<(), String> {
    match name {
        "p_phi" => draw_p_phi(root, series),
        "z_p" => draw_z_p(root, series),
        _ => draw_q_p(root, series),
    }
}

fn caption(series: &MacroSeries, what: &str) -> String {
    if series.name.is_empty() {
        what.to_string()
    } else {
        format!("{} — {what}", series.name)
    }
}

/// Range with a margin; a degenerate range is widened.
fn padded(lo: f64, hi: f64, fraction: f64) -> std::ops::Range<f64> {
    let (lo, hi) = if lo.is_finite() && hi.is_finite() {
        (lo, hi)
    } else {
        (0.0, 1.0)
    };
    let span = (hi - lo).abs().max(1e-12 * hi.abs().max(1.0));
    (lo - fraction * span)..(hi + fraction * span)
}

fn draw_p_phi<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    s: &MacroSeries,
) -> Result<(), String> {
    root.fill(&WHITE).map_err(err)?;
    let e = s.young;
    let phi_lo_data = match s.jamming {
        Some((phi0, _)) => phi0 - 0.03,
        None => s.rows.iter().map(|r| r.phi).fold(f64::INFINITY, f64::min),
    };
    let pts: Vec<(f64, f64)> = s
        .rows
        .iter()
        .filter(|r| r.phi >= phi_lo_data && r.phi.is_finite() && r.p_c.is_finite())
        .map(|r| (r.phi, r.p_c / e))
        .collect();
    let phi_hi = pts.iter().map(|p| p.0).fold(f64::NEG_INFINITY, f64::max);
    let phi_lo = pts.iter().map(|p| p.0).fold(f64::INFINITY, f64::min);
    let reference: Vec<(f64, f64)> = match (s.jamming, s.incompressible) {
        (Some((phi0, z0)), Some(true) | None) if phi_hi > phi0 => {
            let r = CantorReference::new(phi0, z0);
            (0..=200)
                .map(|k| phi0 + (phi_hi - phi0) * k as f64 / 200.0)
                .map(|phi| (phi, r.mean_stress(phi, e) / e))
                .collect()
        }
        _ => Vec::new(),
    };
    let p_hi = pts
        .iter()
        .chain(&reference)
        .map(|p| p.1)
        .fold(0.0f64, f64::max);
    let mut chart = ChartBuilder::on(root)
        .caption(caption(s, "mean stress against packing fraction"), font(24))
        .margin(20)
        .x_label_area_size(50)
        .y_label_area_size(80)
        .build_cartesian_2d(padded(phi_lo, phi_hi, 0.02), padded(0.0, p_hi, 0.05))
        .map_err(err)?;
    chart
        .configure_mesh()
        .x_desc("packing fraction φ")
        .y_desc("p_c / E")
        .axis_desc_style(font(18))
        .label_style(font(14))
        .y_label_formatter(&|v| tick(*v, p_hi))
        .draw()
        .map_err(err)?;
    let blue = RGBColor(31, 119, 180);
    chart
        .draw_series(LineSeries::new(pts.iter().copied(), blue.stroke_width(2)))
        .map_err(err)?
        .label("sdem")
        .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], blue.stroke_width(2)));
    if !reference.is_empty() {
        let (phi0, z0) = s.jamming.unwrap();
        let red = RGBColor(214, 39, 40);
        chart
            .draw_series(DashedLineSeries::new(
                reference.iter().copied(),
                8,
                5,
                red.stroke_width(2),
            ))
            .map_err(err)?
            .label(format!("eq. 69 (φ0 = {phi0:.4}, Z0 = {z0:.2})"))
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], red.stroke_width(2)));
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperLeft)
        .label_font(font(16))
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()
        .map_err(err)?;
    Ok(())
}

fn draw_z_p<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    s: &MacroSeries,
) -> Result<(), String> {
    root.fill(&WHITE).map_err(err)?;
    let e = s.young;
    let rows = loaded_rows(s);
    let (p_lo, p_hi) = rows.iter().fold((f64::INFINITY, 0.0f64), |(lo, hi), r| {
        (lo.min(r.p_c / e), hi.max(r.p_c / e))
    });
    let (p_lo, p_hi) = if rows.is_empty() {
        (1e-6, 1.0)
    } else {
        (p_lo.max(1e-12), p_hi.max(p_lo * 10.0))
    };
    let z_hi = rows.iter().map(|r| r.z.max(r.z_nr)).fold(0.0f64, f64::max);
    let mut chart = ChartBuilder::on(root)
        .caption(
            caption(s, "coordination number against mean stress"),
            font(24),
        )
        .margin(20)
        .x_label_area_size(50)
        .y_label_area_size(60)
        .build_cartesian_2d(
            (p_lo / 1.5..p_hi * 1.5).log_scale(),
            0.0..(z_hi * 1.08).max(1.0),
        )
        .map_err(err)?;
    chart
        .configure_mesh()
        .x_desc("p_c / E")
        .y_desc("coordination number")
        .axis_desc_style(font(18))
        .label_style(font(14))
        .x_label_formatter(&|v| format!("{v:.0e}"))
        .draw()
        .map_err(err)?;
    let blue = RGBColor(31, 119, 180);
    let orange = RGBColor(255, 127, 14);
    chart
        .draw_series(LineSeries::new(
            rows.iter().map(|r| (r.p_c / e, r.z)),
            blue.stroke_width(2),
        ))
        .map_err(err)?
        .label("z (all grains)")
        .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], blue.stroke_width(2)));
    chart
        .draw_series(LineSeries::new(
            rows.iter().map(|r| (r.p_c / e, r.z_nr)),
            orange.stroke_width(2),
        ))
        .map_err(err)?
        .label("z_nr (rattlers removed)")
        .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], orange.stroke_width(2)));
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::LowerRight)
        .label_font(font(16))
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()
        .map_err(err)?;
    Ok(())
}

fn draw_q_p<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    s: &MacroSeries,
) -> Result<(), String> {
    root.fill(&WHITE).map_err(err)?;
    let e = s.young;
    let pts: Vec<(f64, f64)> = loaded_rows(s)
        .iter()
        .filter(|r| r.q_c.is_finite())
        .map(|r| (r.p_c / e, r.q_c / e))
        .collect();
    let p_hi = pts.iter().map(|p| p.0).fold(0.0f64, f64::max);
    let q_lo = pts.iter().map(|p| p.1).fold(0.0f64, f64::min);
    let q_hi = pts.iter().map(|p| p.1).fold(0.0f64, f64::max);
    // The same scale on both axes' spans is not needed; keep q's sign visible around 0.
    let q_span = (q_hi - q_lo).max(1e-3 * p_hi.max(1e-12));
    let mut chart = ChartBuilder::on(root)
        .caption(caption(s, "deviatoric against mean stress"), font(24))
        .margin(20)
        .x_label_area_size(50)
        .y_label_area_size(80)
        .build_cartesian_2d(
            padded(0.0, p_hi.max(1e-12), 0.03),
            (q_lo - 0.05 * q_span)..(q_hi + 0.05 * q_span),
        )
        .map_err(err)?;
    chart
        .configure_mesh()
        .x_desc("p_c / E")
        .y_desc("q_c / E")
        .axis_desc_style(font(18))
        .label_style(font(14))
        .x_label_formatter(&|v| tick(*v, p_hi))
        .y_label_formatter(&|v| tick(*v, q_span))
        .draw()
        .map_err(err)?;
    let blue = RGBColor(31, 119, 180);
    chart
        .draw_series(LineSeries::new(pts.iter().copied(), blue.stroke_width(1)))
        .map_err(err)?;
    chart
        .draw_series(pts.iter().map(|&p| Circle::new(p, 2, blue.filled())))
        .map_err(err)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn jamming_fallback_is_the_first_loaded_row() {
        let rows: Vec<Measures> = [(0.80, 0.0, 0.0), (0.83, 2e-5, 4.1), (0.85, 1e-3, 4.5)]
            .iter()
            .map(|&(phi, p_c, z_nr)| Measures {
                phi,
                p_c,
                z_nr,
                ..Default::default()
            })
            .collect();
        assert_eq!(detect_jamming(&rows, 1.0), Some((0.83, 4.1)));
    }
}
