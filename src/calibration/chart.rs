//! The calibration chart (SDEM paper fig. 7c/d): simulated force (markers) and the fitted
//! law (lines) against the box strain, one panel per hyperelastic law, one colour per nu.
//! Written as plain SVG (text is left to the viewer's fonts, nothing to embed).

use std::fmt::Write;

use super::LawCalibration;

const COLOURS: [&str; 8] = [
    "#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2", "#17becf",
];

fn nice_step(range: f64) -> f64 {
    let raw = range / 5.0;
    let p = 10f64.powf(raw.log10().floor());
    for m in [1.0, 2.0, 2.5, 5.0, 10.0] {
        if m * p >= raw {
            return m * p;
        }
    }
    10.0 * p
}

pub(crate) fn svg(laws: &[LawCalibration], final_side: f64) -> String {
    let (pw, ph) = (460.0, 360.0);
    let (ml, mr, mt, mb) = (70.0, 20.0, 40.0, 55.0);
    let width = pw * laws.len() as f64;
    let height = ph + 40.0;
    let xmax = 1.0 - final_side;
    let mut ymax: f64 = 0.0;
    for l in laws {
        for s in &l.steps {
            ymax = ymax.max(s.force);
        }
    }
    let ystep = nice_step(ymax.max(1e-12));
    let ymax = (ymax / ystep).ceil() * ystep;
    let xstep = nice_step(xmax);
    let mut out = String::new();
    let _ = writeln!(
        out,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{height}" viewBox="0 0 {width} {height}" font-family="DejaVu Sans, Arial, sans-serif" font-size="12">"#
    );
    let _ = writeln!(out, r#"<rect width="100%" height="100%" fill="white"/>"#);
    for (p, law) in laws.iter().enumerate() {
        let x0 = p as f64 * pw + ml;
        let y0 = mt;
        let (w, h) = (pw - ml - mr, ph - mt - mb);
        let sx = |x: f64| x0 + w * x / xmax;
        let sy = |y: f64| y0 + h * (1.0 - y / ymax);
        let _ = writeln!(
            out,
            r#"<text x="{}" y="20" text-anchor="middle" font-size="14">{}: a = {:.3}, b = {:.3} (RMS error {:.1}%)</text>"#,
            x0 + w / 2.0,
            law.law.name(),
            law.fit.a,
            law.fit.b,
            100.0 * law.fit.rms_relative_error
        );
        let _ = writeln!(
            out,
            r#"<rect x="{x0}" y="{y0}" width="{w}" height="{h}" fill="none" stroke="black"/>"#
        );
        let mut t = 0.0;
        while t <= xmax + 1e-12 {
            let _ = writeln!(
                out,
                r##"<line x1="{0}" y1="{1}" x2="{0}" y2="{2}" stroke="#ddd"/><text x="{0}" y="{3}" text-anchor="middle">{4}</text>"##,
                sx(t),
                y0,
                y0 + h,
                y0 + h + 16.0,
                trim(t)
            );
            t += xstep;
        }
        let mut t = 0.0;
        while t <= ymax + 1e-12 {
            let _ = writeln!(
                out,
                r##"<line x1="{0}" y1="{1}" x2="{2}" y2="{1}" stroke="#ddd"/><text x="{3}" y="{4}" text-anchor="end">{5}</text>"##,
                x0,
                sy(t),
                x0 + w,
                x0 - 6.0,
                sy(t) + 4.0,
                trim(t)
            );
            t += ystep;
        }
        let _ = writeln!(
            out,
            r#"<text x="{}" y="{}" text-anchor="middle">box strain 1 - 2h (diameter 1)</text>"#,
            x0 + w / 2.0,
            y0 + h + 36.0
        );
        let _ = writeln!(
            out,
            r#"<text x="{0}" y="{1}" text-anchor="middle" transform="rotate(-90 {0} {1})">wall force F / (E x unit thickness), compression +</text>"#,
            x0 - 52.0,
            y0 + h / 2.0
        );
        let mut nus: Vec<f64> = law.steps.iter().map(|s| s.nu).collect();
        nus.dedup();
        for (k, nu) in nus.iter().enumerate() {
            let c = COLOURS[k % COLOURS.len()];
            let steps: Vec<_> = law.steps.iter().filter(|s| s.nu == *nu).collect();
            let mut path = String::new();
            for s in &steps {
                let fm = law.fit.model_force(s.contact_length, s.dn, 1.0);
                if fm.is_finite() && s.contact_length > 0.0 {
                    let cmd = if path.is_empty() { 'M' } else { 'L' };
                    let _ = write!(
                        path,
                        "{cmd}{:.2},{:.2} ",
                        sx(1.0 - 2.0 * s.h),
                        sy(fm.min(ymax))
                    );
                }
                let _ = writeln!(
                    out,
                    r#"<circle cx="{:.2}" cy="{:.2}" r="2.5" fill="none" stroke="{c}"/>"#,
                    sx(1.0 - 2.0 * s.h),
                    sy(s.force)
                );
            }
            let _ = writeln!(
                out,
                r#"<path d="{path}" fill="none" stroke="{c}" stroke-width="1.5"/>"#
            );
            let ly = y0 + 14.0 + 16.0 * k as f64;
            let _ = writeln!(
                out,
                r#"<line x1="{0}" y1="{1}" x2="{2}" y2="{1}" stroke="{c}" stroke-width="1.5"/><text x="{3}" y="{4}">nu = {nu}</text>"#,
                x0 + 10.0,
                ly,
                x0 + 30.0,
                x0 + 36.0,
                ly + 4.0
            );
        }
        let ly = y0 + 14.0 + 16.0 * nus.len() as f64;
        let _ = writeln!(
            out,
            r#"<circle cx="{}" cy="{ly}" r="2.5" fill="none" stroke="black"/><text x="{}" y="{}">meshfree; lines: fitted law</text>"#,
            x0 + 20.0,
            x0 + 36.0,
            ly + 4.0
        );
    }
    out.push_str("</svg>\n");
    out
}

fn trim(v: f64) -> String {
    let s = format!("{v:.4}");
    let s = s.trim_end_matches('0').trim_end_matches('.');
    if s.is_empty() || s == "-0" {
        "0".into()
    } else {
        s.into()
    }
}
