//! Star-shaped grain contours (SPEC §10b): discs, polygons (from files) and random Fourier
//! shape descriptors; field-node placement inside a contour.
//!
//! A contour is described by its radius function `r(θ) > 0` about the grain's centre (the origin
//! of the grain's reference frame). Star-shapedness is what lets one number per direction
//! describe the grain, what makes "inside" a simple test (`|x| < r(atan2 x)`), and what lets the
//! interior be filled by scaled copies of the contour ([`place_nodes`]).

use std::f64::consts::{PI, TAU};
use std::fmt::Write as _;
use std::path::Path;

use super::MeshfreeError;
use super::discretization::{DiscNodes, NodeDensity};
use super::rpim::SUPPORT_NEIGHBOURS;
use crate::geometry::angle::{atan2, cos, sin, sin_cos};
use crate::portable::{hypot, powf};

/// One term `amplitude cos(n θ + phase)` of a Fourier contour (amplitude relative to `r0`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FourierMode {
    pub n: u32,
    pub amplitude: f64,
    pub phase: f64,
}

/// A star-shaped grain contour about its centre (the origin of its reference frame), as the
/// radius function `r(θ) > 0`.
#[derive(Debug, Clone, PartialEq)]
pub enum StarShape {
    Disc {
        radius: f64,
    },
    /// `r(θ) = r0 (1 + Σ_n amplitude_n cos(n θ + phase_n))`, modes `n >= 2` (SPEC §10b). Mode 1
    /// would be (to first order) a shift of the centre and mode 0 a change of `r0`, so both are
    /// rejected. The origin is the centre of the radius function, not exactly the area centroid
    /// (modes interact at second order): see [`StarShape::centroid`].
    Fourier {
        r0: f64,
        modes: Vec<FourierMode>,
    },
    /// A closed polygon, counter-clockwise, star-shaped about the origin (vertices relative to
    /// the centre).
    Polygon {
        vertices: Vec<[f64; 2]>,
    },
}

/// Parameters of [`StarShape::random_fourier`] ("sand-like" grains).
///
/// The spectrum follows the Fourier-descriptor analyses of real sands (Das 2007; Mollon & Zhao
/// 2012, the seed's ref. 39): `D_2` (elongation) carries most of the energy, around 0.05–0.1 of
/// `r0`, and the following descriptors decay as a power law, `D_n ≈ D_2 (2/n)^decay` with
/// `decay ≈ 2`, up to `n = 8` (beyond that the "roughness" descriptors are ~1e-3 and irrelevant
/// at the node spacings of a 100-node grain). Each `D_n` (n ≥ 3) is multiplied by a random
/// factor in `[1 - jitter, 1 + jitter]` so that grains differ in angularity as well as in
/// orientation; phases are uniform in `[0, 2π)`.
#[derive(Debug, Clone, PartialEq)]
pub struct FourierParams {
    /// `D_2 / r0` is drawn uniformly in `[d2_range[0], d2_range[1]]`.
    pub d2_range: [f64; 2],
    /// Power-law exponent of `D_n / D_2 = (2/n)^decay`.
    pub decay: f64,
    /// Highest mode (inclusive), `>= 2`.
    pub max_mode: u32,
    /// Relative random spread of `D_n`, n ≥ 3, in `[0, 1)`.
    pub jitter: f64,
    /// Smallest radius of curvature allowed at concave points, relative to `r0`. A draw whose
    /// contour curls more tightly is redrawn (new phases), and after repeated failures the modes
    /// `n >= 3` are damped: this keeps the contour free of cusp-like dents that a node spacing of
    /// ~0.2 `r0` could not resolve.
    pub min_concave_radius: f64,
}

impl Default for FourierParams {
    fn default() -> Self {
        Self {
            d2_range: [0.05, 0.1],
            decay: 2.0,
            max_mode: 8,
            jitter: 0.3,
            min_concave_radius: 0.5,
        }
    }
}

/// What is wrong with a polygon (vertex indices 0-based, edge `i` runs from vertex `i` to
/// `i + 1`). Kept structured so that the file reader can name lines instead of indices.
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum PolygonDefect {
    TooFew(usize),
    NonFinite(usize),
    Duplicate(usize),
    Clockwise,
    Crossing {
        e1: usize,
        e2: usize,
        at: [f64; 2],
    },
    /// Vertex `i + 1` is not strictly counter-clockwise of vertex `i` as seen from the origin.
    NotStar {
        i: usize,
    },
    /// The angles go around the origin more than once (or the origin is outside).
    Winding(f64),
}

impl PolygonDefect {
    /// Message with vertices named by `name(i)` (an index, or a file line).
    fn describe(&self, n: usize, name: &dyn Fn(usize) -> String) -> String {
        match *self {
            Self::TooFew(k) => format!("a polygon needs at least 3 vertices, got {k}"),
            Self::NonFinite(i) => format!("{} is not a finite number", name(i)),
            Self::Duplicate(i) => format!(
                "{} repeats the previous vertex (zero-length edge); remove it",
                name(i)
            ),
            Self::Clockwise => {
                "vertices are clockwise; give them counter-clockwise (reverse the order)".into()
            }
            Self::Crossing { e1, e2, at } => format!(
                "self-intersecting polygon: edge {}→{} crosses edge {}→{} at ({:.6}, {:.6})",
                name(e1),
                name((e1 + 1) % n),
                name(e2),
                name((e2 + 1) % n),
                at[0],
                at[1]
            ),
            Self::NotStar { i } => format!(
                "not star-shaped about its centre: {} is not seen counter-clockwise after {} \
                 from the centre (every vertex must be visible from the centre, with polar \
                 angles strictly increasing counter-clockwise)",
                name((i + 1) % n),
                name(i)
            ),
            Self::Winding(turns) => format!(
                "not star-shaped about its centre: the vertices turn {turns:.3} times around it \
                 instead of once"
            ),
        }
    }
}

fn cross(a: [f64; 2], b: [f64; 2]) -> f64 {
    a[0] * b[1] - a[1] * b[0]
}

fn sub(a: [f64; 2], b: [f64; 2]) -> [f64; 2] {
    [a[0] - b[0], a[1] - b[1]]
}

fn norm(a: [f64; 2]) -> f64 {
    hypot(a[0], a[1])
}

/// Signed area (positive when counter-clockwise) of a closed polygon.
pub fn polygon_area(v: &[[f64; 2]]) -> f64 {
    let n = v.len();
    0.5 * (0..n).map(|i| cross(v[i], v[(i + 1) % n])).sum::<f64>()
}

/// Area centroid of a closed polygon (non-zero area).
pub fn polygon_centroid(v: &[[f64; 2]]) -> [f64; 2] {
    let n = v.len();
    // Relative to the first vertex to limit cancellation for polygons far from the origin.
    let o = v[0];
    let (mut a, mut cx, mut cy) = (0.0, 0.0, 0.0);
    for i in 0..n {
        let p = sub(v[i], o);
        let q = sub(v[(i + 1) % n], o);
        let c = cross(p, q);
        a += c;
        cx += (p[0] + q[0]) * c;
        cy += (p[1] + q[1]) * c;
    }
    [o[0] + cx / (3.0 * a), o[1] + cy / (3.0 * a)]
}

/// Intersection point of segments `ab` and `cd` if they touch or cross.
///
/// Orientation tests with a tolerance relative to the segments' size: nearly collinear
/// segments (consecutive nodes along a straight polygon edge, whose cross products are
/// rounding noise) are handled as collinear, so they are reported only if they overlap.
pub(crate) fn segment_intersection(
    a: [f64; 2],
    b: [f64; 2],
    c: [f64; 2],
    d: [f64; 2],
) -> Option<[f64; 2]> {
    let r = sub(b, a);
    let s = sub(d, c);
    let size = norm(r).max(norm(s)).max(norm(sub(c, a)));
    let tol = 1e-12 * size * size;
    let sign = |x: f64| {
        if x > tol {
            1
        } else if x < -tol {
            -1
        } else {
            0
        }
    };
    let o1 = sign(cross(r, sub(c, a)));
    let o2 = sign(cross(r, sub(d, a)));
    let o3 = sign(cross(s, sub(a, c)));
    let o4 = sign(cross(s, sub(b, c)));
    if o1 * o2 < 0 && o3 * o4 < 0 {
        let t = cross(sub(c, a), s) / cross(r, s);
        return Some([a[0] + t * r[0], a[1] + t * r[1]]);
    }
    let slack = 1e-12 * size;
    let on = |p: [f64; 2], a: [f64; 2], b: [f64; 2]| {
        p[0] >= a[0].min(b[0]) - slack
            && p[0] <= a[0].max(b[0]) + slack
            && p[1] >= a[1].min(b[1]) - slack
            && p[1] <= a[1].max(b[1]) + slack
    };
    if o1 == 0 && on(c, a, b) {
        Some(c)
    } else if o2 == 0 && on(d, a, b) {
        Some(d)
    } else if o3 == 0 && on(a, c, d) {
        Some(a)
    } else if o4 == 0 && on(b, c, d) {
        Some(b)
    } else {
        None
    }
}

/// First pair of non-adjacent edges that touch or cross, O(n²) (polygons here have at most a
/// few hundred vertices).
pub(crate) fn first_crossing(v: &[[f64; 2]]) -> Option<(usize, usize, [f64; 2])> {
    let n = v.len();
    for i in 0..n {
        for j in i + 1..n {
            if j == i + 1 || (i == 0 && j == n - 1) {
                continue; // adjacent edges share a vertex
            }
            if let Some(p) = segment_intersection(v[i], v[(i + 1) % n], v[j], v[(j + 1) % n]) {
                return Some((i, j, p));
            }
        }
    }
    None
}

/// Checks a polygon given relative to its centre.
pub(crate) fn polygon_defect(v: &[[f64; 2]]) -> Option<PolygonDefect> {
    let n = v.len();
    if n < 3 {
        return Some(PolygonDefect::TooFew(n));
    }
    if let Some(i) = v
        .iter()
        .position(|p| !(p[0].is_finite() && p[1].is_finite()))
    {
        return Some(PolygonDefect::NonFinite(i));
    }
    if let Some(i) = (0..n).find(|&i| v[i] == v[(i + n - 1) % n]) {
        return Some(PolygonDefect::Duplicate(i));
    }
    if let Some((e1, e2, at)) = first_crossing(v) {
        return Some(PolygonDefect::Crossing { e1, e2, at });
    }
    if polygon_area(v) <= 0.0 {
        return Some(PolygonDefect::Clockwise);
    }
    let mut turn = 0.0;
    for i in 0..n {
        let (a, b) = (v[i], v[(i + 1) % n]);
        let c = cross(a, b);
        // A vertex at the centre, or an edge through it, is not "strictly visible" either.
        let scale = norm(a) * norm(b);
        if c <= 1e-12 * scale {
            return Some(PolygonDefect::NotStar { i });
        }
        turn += atan2(c, a[0] * b[0] + a[1] * b[1]);
    }
    let turns = turn / TAU;
    if (turns - 1.0).abs() > 1e-9 {
        return Some(PolygonDefect::Winding(turns));
    }
    None
}

/// Bounds `[Σ|a|, Σ n|a|, Σ n²|a|]` (relative to r0) on `|r/r0 - 1|`, `|r'|/r0`, `|r''|/r0`.
fn fourier_bounds(modes: &[FourierMode]) -> [f64; 3] {
    let mut b = [0.0; 3];
    for m in modes {
        let a = m.amplitude.abs();
        let n = f64::from(m.n);
        b[0] += a;
        b[1] += n * a;
        b[2] += n * n * a;
    }
    b
}

fn fourier_r(r0: f64, modes: &[FourierMode], theta: f64) -> f64 {
    r0 * (1.0
        + modes
            .iter()
            .map(|m| m.amplitude * cos(f64::from(m.n) * theta + m.phase))
            .sum::<f64>())
}

/// `r, r', r''` of a Fourier contour.
fn fourier_derivatives(r0: f64, modes: &[FourierMode], theta: f64) -> [f64; 3] {
    let mut out = [1.0, 0.0, 0.0];
    for m in modes {
        let n = f64::from(m.n);
        let (s, c) = sin_cos(n * theta + m.phase);
        out[0] += m.amplitude * c;
        out[1] -= m.amplitude * n * s;
        out[2] -= m.amplitude * n * n * c;
    }
    out.map(|x| x * r0)
}

/// Uniform `f64` in `[0, 1)` from 53 random bits of one `u64` (portable, as in `sample`).
pub(crate) fn unit_f64<R: rand::Rng + ?Sized>(rng: &mut R) -> f64 {
    const SCALE: f64 = 1.0 / (1u64 << 53) as f64;
    (rng.next_u64() >> 11) as f64 * SCALE
}

/// Angular resolution used to sample smooth contours (Fourier, disc) for extrema and for
/// arc-length tables: enough points per wavelength of the highest mode.
fn smooth_resolution(modes: &[FourierMode]) -> usize {
    let nmax = modes.iter().map(|m| m.n).max().unwrap_or(0) as usize;
    (64 * nmax).max(1024)
}

impl StarShape {
    /// The contour's distance from the centre in direction `theta` (radians).
    pub fn radius_at(&self, theta: f64) -> f64 {
        match self {
            Self::Disc { radius } => *radius,
            Self::Fourier { r0, modes } => fourier_r(*r0, modes, theta),
            Self::Polygon { vertices } => {
                let d = [cos(theta), sin(theta)];
                let n = vertices.len();
                for i in 0..n {
                    let (a, b) = (vertices[i], vertices[(i + 1) % n]);
                    // The ray t d, t > 0, crosses edge ab if d lies in the cone (a, b); for a
                    // star-shaped polygon exactly one cone holds d (two when d hits a vertex,
                    // with the same answer).
                    if cross(a, d) >= 0.0 && cross(d, b) >= 0.0 {
                        let e = sub(b, a);
                        let denom = cross(d, e);
                        if denom > 0.0 {
                            return cross(a, e) / denom;
                        }
                    }
                }
                f64::NAN // not star-shaped about the origin (validate() says why)
            }
        }
    }

    /// An upper bound of `r(θ)` (exact for discs and polygons; for Fourier shapes the sampled
    /// maximum plus a rigorous bound on what lies between samples), used for the
    /// circumscribed-circle broad phase.
    pub fn max_radius(&self) -> f64 {
        match self {
            Self::Disc { radius } => *radius,
            Self::Polygon { vertices } => vertices.iter().map(|v| norm(*v)).fold(0.0, f64::max),
            Self::Fourier { r0, modes } => {
                let m = smooth_resolution(modes);
                let dt = TAU / m as f64;
                let max = (0..m)
                    .map(|k| fourier_r(*r0, modes, k as f64 * dt))
                    .fold(f64::MIN, f64::max);
                // At the maximum r' = 0, so the nearest sample is below it by at most
                // max|r''| (dt/2)^2 / 2.
                max + 0.125 * r0 * fourier_bounds(modes)[2] * dt * dt
            }
        }
    }

    /// A lower bound of `r(θ)` (exact for discs and polygons up to sampling of the edges'
    /// nearest points, sampled minus a rigorous margin for Fourier shapes).
    pub fn min_radius(&self) -> f64 {
        match self {
            Self::Disc { radius } => *radius,
            Self::Polygon { vertices } => {
                let n = vertices.len();
                (0..n)
                    .map(|i| point_segment_distance([0.0, 0.0], vertices[i], vertices[(i + 1) % n]))
                    .fold(f64::MAX, f64::min)
            }
            Self::Fourier { r0, modes } => {
                let m = smooth_resolution(modes);
                let dt = TAU / m as f64;
                let min = (0..m)
                    .map(|k| fourier_r(*r0, modes, k as f64 * dt))
                    .fold(f64::MAX, f64::min);
                min - 0.125 * r0 * fourier_bounds(modes)[2] * dt * dt
            }
        }
    }

    /// Area enclosed by the contour: exact for discs and polygons; for Fourier shapes
    /// `1/2 ∫ r² dθ` by the trapezoidal rule with more than `2 n_max` points, which is exact
    /// for the trigonometric polynomial `r²` (up to rounding).
    pub fn area(&self) -> f64 {
        match self {
            Self::Disc { radius } => PI * radius * radius,
            Self::Polygon { vertices } => polygon_area(vertices),
            Self::Fourier { r0, modes } => {
                let nmax = modes.iter().map(|m| m.n).max().unwrap_or(0) as usize;
                let m = (4 * nmax + 8).max(64);
                let dt = TAU / m as f64;
                0.5 * dt
                    * (0..m)
                        .map(|k| fourier_r(*r0, modes, k as f64 * dt).powi(2))
                        .sum::<f64>()
            }
        }
    }

    /// Area centroid relative to the centre: zero for discs, exact for polygons, from a fine
    /// polygon of the contour for Fourier shapes.
    pub fn centroid(&self) -> [f64; 2] {
        match self {
            Self::Disc { .. } => [0.0, 0.0],
            Self::Polygon { vertices } => polygon_centroid(vertices),
            Self::Fourier { modes, .. } => {
                polygon_centroid(&self.outline(smooth_resolution(modes)))
            }
        }
    }

    /// Checks the shape: finite positive sizes, `r > 0` everywhere, and for polygons at least 3
    /// distinct vertices, no self-intersection, counter-clockwise and star-shaped about the
    /// origin (polar angles of the vertices strictly increasing, once around).
    pub fn validate(&self) -> Result<(), MeshfreeError> {
        match self {
            Self::Disc { radius } => {
                if !(radius.is_finite() && *radius > 0.0) {
                    return Err(MeshfreeError::BadInput(format!(
                        "disc radius must be positive and finite, got {radius}"
                    )));
                }
            }
            Self::Fourier { r0, modes } => {
                if !(r0.is_finite() && *r0 > 0.0) {
                    return Err(MeshfreeError::BadInput(format!(
                        "Fourier shape: r0 must be positive and finite, got {r0}"
                    )));
                }
                for m in modes {
                    if !(m.amplitude.is_finite() && m.phase.is_finite()) {
                        return Err(MeshfreeError::BadInput(format!(
                            "Fourier shape: mode n = {} has a non-finite amplitude ({}) or \
                             phase ({})",
                            m.n, m.amplitude, m.phase
                        )));
                    }
                    if m.n < 2 || m.n > 4096 {
                        return Err(MeshfreeError::BadInput(format!(
                            "Fourier shape: mode n = {} is outside 2..=4096 (n = 0 is a change \
                             of r0, n = 1 a shift of the centre)",
                            m.n
                        )));
                    }
                }
                let b = fourier_bounds(modes);
                if b[0] >= 1.0 {
                    // The cheap sufficient condition fails: look at the contour itself.
                    let min = self.min_radius();
                    if min <= 0.0 {
                        return Err(MeshfreeError::BadInput(format!(
                            "Fourier shape: the radius is not positive everywhere (lower bound \
                             {min:.4e}); the relative amplitudes sum to {:.4}, keep it below 1",
                            b[0]
                        )));
                    }
                }
            }
            Self::Polygon { vertices } => {
                if let Some(d) = polygon_defect(vertices) {
                    return Err(MeshfreeError::BadInput(format!(
                        "polygon: {}",
                        d.describe(vertices.len(), &|i| format!("vertex {i}"))
                    )));
                }
            }
        }
        Ok(())
    }

    /// A "sand-like" Fourier grain (see [`FourierParams`] for the spectrum and its sources).
    /// Deterministic for a given generator state. Draws whose contour has a concave radius of
    /// curvature below `min_concave_radius r0` are redrawn; after 20 failures the modes n ≥ 3
    /// are damped by 0.8 per further failure, so the function always returns a valid shape.
    ///
    /// # Panics
    /// If the parameters are out of range (`r0 <= 0`, `max_mode < 2`, an empty or negative
    /// `d2_range`, `jitter` outside `[0, 1)`): they are programmer input, not data.
    pub fn random_fourier<R: rand::Rng + ?Sized>(
        r0: f64,
        rng: &mut R,
        params: &FourierParams,
    ) -> Self {
        let [d2a, d2b] = params.d2_range;
        assert!(r0.is_finite() && r0 > 0.0, "r0 must be positive, got {r0}");
        assert!(
            params.max_mode >= 2 && params.max_mode <= 64,
            "max_mode must be in 2..=64, got {}",
            params.max_mode
        );
        assert!(
            0.0 <= d2a && d2a <= d2b && d2b < 0.5,
            "d2_range must satisfy 0 <= lo <= hi < 0.5, got {:?}",
            params.d2_range
        );
        assert!(
            (0.0..1.0).contains(&params.jitter),
            "jitter must be in [0, 1), got {}",
            params.jitter
        );
        assert!(
            params.decay.is_finite() && params.decay >= 0.0,
            "decay must be >= 0, got {}",
            params.decay
        );
        let d2 = d2a + (d2b - d2a) * unit_f64(rng);
        let mut base: Vec<f64> = (2..=params.max_mode)
            .map(|n| {
                if n == 2 {
                    d2
                } else {
                    let jitter = 1.0 + params.jitter * (2.0 * unit_f64(rng) - 1.0);
                    d2 * powf(2.0 / f64::from(n), params.decay) * jitter
                }
            })
            .collect();
        // Keep r > 0 with a margin whatever the phases.
        let sum: f64 = base.iter().sum();
        if sum > 0.6 {
            base.iter_mut().for_each(|a| *a *= 0.6 / sum);
        }
        let mut attempt = 0;
        loop {
            let damp = 0.8f64.powi((attempt - 20).max(0));
            let modes: Vec<FourierMode> = base
                .iter()
                .enumerate()
                .map(|(k, &a)| FourierMode {
                    n: k as u32 + 2,
                    amplitude: if k == 0 { a } else { a * damp },
                    phase: TAU * unit_f64(rng),
                })
                .collect();
            let shape = Self::Fourier { r0, modes };
            if shape.min_concave_radius() >= params.min_concave_radius * r0 || attempt > 200 {
                return shape;
            }
            attempt += 1;
        }
    }

    /// Smallest radius of curvature at concave points (infinite for a convex contour); sampled.
    pub fn min_concave_radius(&self) -> f64 {
        match self {
            Self::Disc { .. } => f64::INFINITY,
            Self::Polygon { vertices } => {
                let n = vertices.len();
                let reflex = (0..n).any(|i| {
                    cross(
                        sub(vertices[i], vertices[(i + n - 1) % n]),
                        sub(vertices[(i + 1) % n], vertices[i]),
                    ) < 0.0
                });
                if reflex { 0.0 } else { f64::INFINITY }
            }
            Self::Fourier { r0, modes } => {
                let m = smooth_resolution(modes);
                let mut worst = f64::INFINITY;
                for k in 0..m {
                    let [r, r1, r2] = fourier_derivatives(*r0, modes, TAU * k as f64 / m as f64);
                    // Signed curvature of a polar curve.
                    let kappa = (r * r + 2.0 * r1 * r1 - r * r2) / powf(r * r + r1 * r1, 1.5);
                    if kappa < 0.0 {
                        worst = worst.min(-1.0 / kappa);
                    }
                }
                worst
            }
        }
    }

    /// A copy rotated by `angle` (radians, counter-clockwise) about the centre.
    pub fn rotated(&self, angle: f64) -> Self {
        match self {
            Self::Disc { radius } => Self::Disc { radius: *radius },
            Self::Fourier { r0, modes } => Self::Fourier {
                r0: *r0,
                // r_new(θ) = r(θ - angle)
                modes: modes
                    .iter()
                    .map(|m| FourierMode {
                        phase: (m.phase - f64::from(m.n) * angle).rem_euclid(TAU),
                        ..*m
                    })
                    .collect(),
            },
            Self::Polygon { vertices } => {
                let (s, c) = sin_cos(angle);
                Self::Polygon {
                    vertices: vertices
                        .iter()
                        .map(|v| [c * v[0] - s * v[1], s * v[0] + c * v[1]])
                        .collect(),
                }
            }
        }
    }

    /// Re-centres a polygon on its area centroid and returns the shift (the old coordinates of
    /// the centroid): polygons read from files are given in absolute coordinates. Discs and
    /// Fourier shapes are defined about their centre; they are left unchanged and `[0, 0]` is
    /// returned.
    pub fn recentre(&mut self) -> [f64; 2] {
        match self {
            Self::Polygon { vertices } if vertices.len() >= 3 && polygon_area(vertices) != 0.0 => {
                let c = polygon_centroid(vertices);
                vertices.iter_mut().for_each(|v| *v = sub(*v, c));
                c
            }
            _ => [0.0, 0.0],
        }
    }

    /// The contour as a closed CCW polygon: the vertices of a polygon; `points` points at
    /// uniform angles (from θ = 0) for discs and Fourier shapes.
    pub fn outline(&self, points: usize) -> Vec<[f64; 2]> {
        match self {
            Self::Polygon { vertices } => vertices.clone(),
            _ => (0..points)
                .map(|k| {
                    let t = TAU * k as f64 / points as f64;
                    let r = self.radius_at(t);
                    [r * cos(t), r * sin(t)]
                })
                .collect(),
        }
    }

    /// Upper bound on how far the true contour lies outside the chords of
    /// [`outline(points)`](Self::outline): zero for polygons; `Δθ²/8 max|x''(θ)|` otherwise, with
    /// `|x''| <= r + 2|r'| + |r''|` bounded term by term.
    pub fn outline_error(&self, points: usize) -> f64 {
        let dt = TAU / points as f64;
        match self {
            Self::Polygon { .. } => 0.0,
            Self::Disc { radius } => 0.125 * dt * dt * radius,
            Self::Fourier { r0, modes } => {
                let [b0, b1, b2] = fourier_bounds(modes);
                0.125 * dt * dt * r0 * (1.0 + b0 + 2.0 * b1 + b2)
            }
        }
    }

    /// Whether `p` (relative to the centre) is inside or on the contour.
    pub fn contains(&self, p: [f64; 2]) -> bool {
        let d = norm(p);
        d == 0.0 || d <= self.radius_at(atan2(p[1], p[0]))
    }
}

/// Distance from `p` to segment `ab`.
pub(crate) fn point_segment_distance(p: [f64; 2], a: [f64; 2], b: [f64; 2]) -> f64 {
    let ab = sub(b, a);
    let ap = sub(p, a);
    let l2 = ab[0] * ab[0] + ab[1] * ab[1];
    let t = if l2 > 0.0 {
        ((ap[0] * ab[0] + ap[1] * ab[1]) / l2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    norm(sub(p, [a[0] + t * ab[0], a[1] + t * ab[1]]))
}

/// Even–odd test: is `p` strictly inside the closed polygon `v`?
pub(crate) fn point_in_polygon(p: [f64; 2], v: &[[f64; 2]]) -> bool {
    let n = v.len();
    let mut inside = false;
    let mut j = n - 1;
    for i in 0..n {
        let (a, b) = (v[i], v[j]);
        if (a[1] > p[1]) != (b[1] > p[1]) {
            let x = a[0] + (p[1] - a[1]) * (b[0] - a[0]) / (b[1] - a[1]);
            if p[0] < x {
                inside = !inside;
            }
        }
        j = i;
    }
    inside
}

/// `count` sand-like Fourier grains ([`StarShape::random_fourier`] with default
/// [`FourierParams`]), `r0` uniform in `[(1 - radius_spread), (1 + radius_spread)] ×
/// mean_radius`, from a ChaCha8 generator seeded with `seed`. For the seed paper's 100-grain
/// example use `radius_spread = 0.2`.
///
/// # Panics
/// If `mean_radius <= 0` or `radius_spread` is outside `[0, 1)`; see [`try_sand_like_sample`].
pub fn sand_like_sample(
    count: usize,
    mean_radius: f64,
    radius_spread: f64,
    seed: u64,
) -> Vec<StarShape> {
    match try_sand_like_sample(count, mean_radius, radius_spread, seed) {
        Ok(v) => v,
        Err(e) => panic!("{e}"),
    }
}

/// [`sand_like_sample`] with its input checked.
pub fn try_sand_like_sample(
    count: usize,
    mean_radius: f64,
    radius_spread: f64,
    seed: u64,
) -> Result<Vec<StarShape>, MeshfreeError> {
    use rand::SeedableRng;
    if !(mean_radius.is_finite() && mean_radius > 0.0) {
        return Err(MeshfreeError::BadInput(format!(
            "mean_radius must be positive and finite, got {mean_radius}"
        )));
    }
    if !(0.0..1.0).contains(&radius_spread) {
        return Err(MeshfreeError::BadInput(format!(
            "radius_spread must be in [0, 1), got {radius_spread}"
        )));
    }
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let params = FourierParams::default();
    Ok((0..count)
        .map(|_| {
            let r0 = mean_radius * (1.0 + radius_spread * (2.0 * unit_f64(&mut rng) - 1.0));
            StarShape::random_fourier(r0, &mut rng, &params)
        })
        .collect())
}

// ---------------------------------------------------------------------------------------------
// Shape files

/// Errors of [`read_shape_file`]; `Display` starts with `file:line`.
#[derive(Debug, thiserror::Error)]
pub enum ShapeFileError {
    #[error("{path}: cannot read the shape file: {source}")]
    Io {
        path: String,
        #[source]
        source: std::io::Error,
    },
    #[error("{path}:{line}: {message}")]
    Parse {
        path: String,
        line: usize,
        message: String,
    },
}

/// Reads grain polygons from a text file, returning each grain's area centroid in the file's
/// coordinates and its polygon re-centred on it.
///
/// Format (one grain per block):
///
/// ```text
/// # comments start with '#', anywhere on a line; blank lines are ignored
/// grain 1          # starts a grain; the id (any text) is optional and used in messages
/// 0.0 0.0          # one vertex per line: x y, separated by spaces, tabs or a comma
/// 1.0, 0.0
/// 0.5 1.0
/// grain            # next grain
/// ...
/// ```
///
/// Vertices may be listed clockwise or counter-clockwise (clockwise blocks are reversed), and a
/// last vertex repeating the first is dropped. Each polygon must be simple and star-shaped
/// about its centroid.
pub fn read_shape_file(path: &Path) -> Result<Vec<([f64; 2], StarShape)>, ShapeFileError> {
    let name = path.display().to_string();
    let text = std::fs::read_to_string(path).map_err(|source| ShapeFileError::Io {
        path: name.clone(),
        source,
    })?;
    parse_shapes(&text, &name)
}

struct Block {
    id: String,
    line: usize,
    vertices: Vec<[f64; 2]>,
    lines: Vec<usize>,
}

/// Parses the text of a shape file (`name` is used in messages).
pub fn parse_shapes(text: &str, name: &str) -> Result<Vec<([f64; 2], StarShape)>, ShapeFileError> {
    let err = |line: usize, message: String| ShapeFileError::Parse {
        path: name.to_string(),
        line,
        message,
    };
    let mut blocks: Vec<Block> = Vec::new();
    for (k, raw) in text.lines().enumerate() {
        let line = k + 1;
        let content = raw.split('#').next().unwrap_or("").trim();
        if content.is_empty() {
            continue;
        }
        let mut words = content.split_whitespace();
        if words
            .next()
            .is_some_and(|w| w.eq_ignore_ascii_case("grain"))
        {
            let id = content[5..].trim();
            blocks.push(Block {
                id: if id.is_empty() {
                    format!("#{}", blocks.len() + 1)
                } else {
                    id.to_string()
                },
                line,
                vertices: Vec::new(),
                lines: Vec::new(),
            });
            continue;
        }
        let tokens: Vec<&str> = content
            .split(|c: char| c == ',' || c.is_whitespace())
            .filter(|t| !t.is_empty())
            .collect();
        let Some(block) = blocks.last_mut() else {
            return Err(err(
                line,
                format!("expected a `grain` line before the first vertex, found `{content}`"),
            ));
        };
        if tokens.len() != 2 {
            return Err(err(
                line,
                format!(
                    "expected a vertex `x y` (two numbers) or a `grain [id]` line, found `{content}`"
                ),
            ));
        }
        let mut xy = [0.0; 2];
        for (slot, t) in xy.iter_mut().zip(&tokens) {
            *slot = match t.parse::<f64>() {
                Ok(v) if v.is_finite() => v,
                _ => {
                    return Err(err(
                        line,
                        format!("expected a finite number for a vertex coordinate, found `{t}`"),
                    ));
                }
            };
        }
        block.vertices.push(xy);
        block.lines.push(line);
    }
    let mut out = Vec::with_capacity(blocks.len());
    for mut b in blocks {
        if b.vertices.len() > 3 && b.vertices.first() == b.vertices.last() {
            b.vertices.pop();
            b.lines.pop();
        }
        if b.vertices.len() < 3 {
            return Err(err(
                b.line,
                format!(
                    "grain {} has {} vertices; a polygon needs at least 3",
                    b.id,
                    b.vertices.len()
                ),
            ));
        }
        if polygon_area(&b.vertices) < 0.0 {
            b.vertices.reverse();
            b.lines.reverse();
        }
        let mut shape = StarShape::Polygon {
            vertices: b.vertices,
        };
        let centre = shape.recentre();
        let StarShape::Polygon { vertices } = &shape else {
            unreachable!()
        };
        if let Some(d) = polygon_defect(vertices) {
            let line = match d {
                PolygonDefect::Crossing { e1, .. } => b.lines[e1],
                PolygonDefect::NotStar { i } => b.lines[(i + 1) % b.lines.len()],
                PolygonDefect::NonFinite(i) | PolygonDefect::Duplicate(i) => b.lines[i],
                _ => b.line,
            };
            let lines = &b.lines;
            let msg = d.describe(vertices.len(), &|i| {
                format!("the vertex on line {}", lines[i])
            });
            return Err(err(
                line,
                format!("grain {} (line {}): {msg}", b.id, b.line),
            ));
        }
        out.push((centre, shape));
    }
    Ok(out)
}

/// Writes grains in the format of [`read_shape_file`], in absolute coordinates (`centre` +
/// contour). Discs and Fourier shapes are written as their [`outline`](StarShape::outline)
/// with `points` vertices. Numbers are written with full precision (round trip exact).
pub fn write_shape_file(
    path: &Path,
    grains: &[([f64; 2], StarShape)],
    points: usize,
) -> std::io::Result<()> {
    let mut s = String::from("# sdem grain shapes: `grain id` then one `x y` vertex per line\n");
    for (k, (c, shape)) in grains.iter().enumerate() {
        let _ = writeln!(s, "grain {}", k + 1);
        for v in shape.outline(points) {
            let _ = writeln!(s, "{:?} {:?}", c[0] + v[0], c[1] + v[1]);
        }
    }
    std::fs::write(path, s)
}

// ---------------------------------------------------------------------------------------------
// Field nodes

/// Field nodes of one grain, reference coordinates relative to its centre: the first
/// `boundary_count` are the contour nodes in CCW order.
#[derive(Debug, Clone, PartialEq)]
pub struct GrainNodes {
    pub positions: Vec<[f64; 2]>,
    pub boundary_count: usize,
}

impl GrainNodes {
    pub fn len(&self) -> usize {
        self.positions.len()
    }

    pub fn is_empty(&self) -> bool {
        self.positions.is_empty()
    }

    /// The boundary nodes (the contour polygon, CCW).
    pub fn boundary(&self) -> &[[f64; 2]] {
        &self.positions[..self.boundary_count]
    }
}

/// A closed polyline with cumulative arc length, used to place points at given arc lengths.
struct ArcTable {
    points: Vec<[f64; 2]>,
    /// `cum[i]` = arc length from point 0 to point i; `cum[n]` = perimeter.
    cum: Vec<f64>,
}

impl ArcTable {
    fn new(points: Vec<[f64; 2]>) -> Self {
        let n = points.len();
        let mut cum = Vec::with_capacity(n + 1);
        cum.push(0.0);
        for i in 0..n {
            let l = norm(sub(points[(i + 1) % n], points[i]));
            cum.push(cum[i] + l);
        }
        Self { points, cum }
    }

    fn perimeter(&self) -> f64 {
        *self.cum.last().unwrap_or(&0.0)
    }

    /// Point at arc length `s` (taken modulo the perimeter).
    fn at(&self, s: f64) -> [f64; 2] {
        let n = self.points.len();
        let s = s.rem_euclid(self.perimeter());
        let i = self.cum.partition_point(|&c| c <= s).clamp(1, n) - 1;
        let l = self.cum[i + 1] - self.cum[i];
        let t = if l > 0.0 { (s - self.cum[i]) / l } else { 0.0 };
        let (a, b) = (self.points[i], self.points[(i + 1) % n]);
        [a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])]
    }
}

/// Turning angle above which a polygon vertex is a "corner" and always a node.
const CORNER_ANGLE: f64 = 20.0 * PI / 180.0;

/// Field nodes of a grain.
///
/// Boundary nodes are placed at (nearly) uniform arc-length spacing `spacing` along the
/// contour (at least 8 of them) and projected radially onto it, so they lie exactly on the
/// contour. Polygon vertices that turn by more than 20° are kept as nodes (sharp corners are
/// resolved) and each stretch between two of them is divided evenly; a finely sampled polygon
/// without such corners is treated as a smooth curve.
///
/// Interior nodes lie on scaled copies `ρ C` of the contour (the star-shaped analogue of the
/// rings of [`DiscNodes`]), with the target spacing `h(ρ) = spacing (1 + grading (1 - ρ))`
/// growing from `spacing` at the contour to `(1 + grading) spacing` at the centre (the meaning
/// of [`NodeDensity::grading`]); rings are `√3/2 h` apart on average (hexagon-like), alternate
/// rings are shifted by half a spacing, and a centre node closes the set. A candidate is
/// dropped when it is closer than `0.5 spacing` to the contour (or outside the boundary-node
/// polygon) or closer than `0.6 h` to an already accepted node, which handles elongated shapes
/// and sharp corners where scaled rings crowd together.
///
/// For a disc whose boundary count `round(2πR / spacing)` is a multiple of 4 this is
/// [`DiscNodes::disc`] itself.
///
/// Fails with [`MeshfreeError::TooCoarse`] below 21 nodes (RPIM supports hold 20 neighbours),
/// with [`MeshfreeError::BadInput`] for an invalid shape, spacing or grading.
pub fn place_nodes(
    shape: &StarShape,
    spacing: f64,
    grading: f64,
) -> Result<GrainNodes, MeshfreeError> {
    shape.validate()?;
    if !(spacing.is_finite() && spacing > 0.0) {
        return Err(MeshfreeError::BadInput(format!(
            "node spacing must be positive and finite, got {spacing}"
        )));
    }
    if !(grading.is_finite() && (0.0..=10.0).contains(&grading)) {
        return Err(MeshfreeError::BadInput(format!(
            "grading must be in [0, 10], got {grading}"
        )));
    }
    let needed = SUPPORT_NEIGHBOURS + 1;
    let rmax = shape.max_radius();
    // Rough count: area / (spacing² √3/2) ≤ π rmax² / (0.87 spacing²).
    let estimate = 4.0 * (rmax / spacing).powi(2);
    if estimate > 2.0e6 {
        return Err(MeshfreeError::BadInput(format!(
            "node spacing {spacing} is too fine for a grain of radius {rmax} (about {estimate:.0} \
             nodes); use a spacing above {:.3e}",
            rmax / 700.0
        )));
    }

    if let StarShape::Disc { radius } = shape {
        let nb = (TAU * radius / spacing).round() as usize;
        if nb >= 8 && nb.is_multiple_of(4) {
            let d = DiscNodes::disc(
                *radius,
                NodeDensity {
                    boundary_nodes: nb,
                    grading,
                },
            )?;
            if d.positions.len() < needed {
                return Err(MeshfreeError::TooCoarse {
                    nodes: d.positions.len(),
                    needed,
                });
            }
            return Ok(GrainNodes {
                positions: d.positions,
                boundary_count: d.boundary_count,
            });
        }
    }

    // The contour as a polyline, and which of its vertices are mandatory nodes.
    let (contour, corners): (Vec<[f64; 2]>, Vec<usize>) = match shape {
        StarShape::Polygon { vertices } => {
            let n = vertices.len();
            let corners = (0..n)
                .filter(|&i| {
                    let a = sub(vertices[i], vertices[(i + n - 1) % n]);
                    let b = sub(vertices[(i + 1) % n], vertices[i]);
                    atan2(cross(a, b), a[0] * b[0] + a[1] * b[1]).abs() > CORNER_ANGLE
                })
                .collect();
            (vertices.clone(), corners)
        }
        StarShape::Disc { .. } => (shape.outline(1024), Vec::new()),
        StarShape::Fourier { modes, .. } => (shape.outline(smooth_resolution(modes)), Vec::new()),
    };
    let table = ArcTable::new(contour);
    let perimeter = table.perimeter();
    let project = |p: [f64; 2]| -> [f64; 2] {
        let t = atan2(p[1], p[0]);
        let r = shape.radius_at(t);
        [r * cos(t), r * sin(t)]
    };

    // Boundary arc positions.
    let mut arcs: Vec<f64> = Vec::new();
    if corners.is_empty() {
        let n = ((perimeter / spacing).round() as usize).max(8);
        arcs.extend((0..n).map(|j| perimeter * j as f64 / n as f64));
    } else {
        let m = corners.len();
        let starts: Vec<f64> = corners.iter().map(|&i| table.cum[i]).collect();
        let lengths: Vec<f64> = (0..m)
            .map(|k| {
                let end = if k + 1 < m {
                    starts[k + 1]
                } else {
                    starts[0] + perimeter
                };
                end - starts[k]
            })
            .collect();
        let mut segments: Vec<usize> = lengths
            .iter()
            .map(|l| ((l / spacing).round() as usize).max(1))
            .collect();
        while segments.iter().sum::<usize>() < 8 {
            // Refine the stretch with the longest pieces.
            let k = (0..m)
                .max_by(|&a, &b| {
                    (lengths[a] / segments[a] as f64).total_cmp(&(lengths[b] / segments[b] as f64))
                })
                .unwrap_or(0);
            segments[k] += 1;
        }
        for k in 0..m {
            for j in 0..segments[k] {
                arcs.push(starts[k] + lengths[k] * j as f64 / segments[k] as f64);
            }
        }
    }
    let mut positions: Vec<[f64; 2]> = arcs.iter().map(|&s| project(table.at(s))).collect();
    let boundary_count = positions.len();
    let boundary = positions.clone();

    // Interior: scaled copies of the contour.
    let h = |rho: f64| spacing * (1.0 + grading * (1.0 - rho));
    // Mean support-function value p = x·n over the contour: 2A / P.
    let p_mean = 2.0 * polygon_area(&boundary) / perimeter;
    let min_to_contour = 0.5 * spacing;
    let far_from_contour = |p: [f64; 2]| {
        point_in_polygon(p, &boundary)
            && (0..boundary_count).all(|i| {
                point_segment_distance(p, boundary[i], boundary[(i + 1) % boundary_count])
                    >= min_to_contour
            })
    };
    let accept = |p: [f64; 2], h_local: f64, positions: &mut Vec<[f64; 2]>| {
        let min_d = 0.6 * h_local;
        if far_from_contour(p) && positions.iter().all(|q| norm(sub(p, *q)) >= min_d) {
            positions.push(p);
        }
    };
    let mut rho = 1.0;
    let mut ring = 1usize;
    loop {
        let s = h(rho);
        let step = 0.5 * 3f64.sqrt() * h(rho - 0.5 * s / p_mean) / p_mean;
        let next = rho - step;
        if next * p_mean < 0.6 * h(next.max(0.0)) {
            break;
        }
        rho = next;
        let hk = h(rho);
        let n = (rho * perimeter / hk).round() as usize;
        if n >= 3 {
            let offset = if ring % 2 == 1 { 0.5 } else { 0.0 };
            for j in 0..n {
                let q = table.at(perimeter * (j as f64 + offset) / n as f64);
                accept([rho * q[0], rho * q[1]], hk, &mut positions);
            }
        }
        ring += 1;
    }
    accept([0.0, 0.0], h(0.0), &mut positions);

    if positions.len() < needed {
        return Err(MeshfreeError::TooCoarse {
            nodes: positions.len(),
            needed,
        });
    }
    Ok(GrainNodes {
        positions,
        boundary_count,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    fn sample_fourier() -> StarShape {
        StarShape::Fourier {
            r0: 1.3,
            modes: vec![
                FourierMode {
                    n: 2,
                    amplitude: 0.08,
                    phase: 0.3,
                },
                FourierMode {
                    n: 3,
                    amplitude: 0.04,
                    phase: 1.1,
                },
                FourierMode {
                    n: 5,
                    amplitude: 0.02,
                    phase: -0.7,
                },
            ],
        }
    }

    /// A non-convex star-shaped polygon (a 5-pointed star, outer radius 1, inner 0.45).
    pub(crate) fn star_polygon() -> StarShape {
        let vertices = (0..10)
            .map(|k| {
                let t = PI * k as f64 / 5.0;
                let r = if k % 2 == 0 { 1.0 } else { 0.45 };
                [r * t.cos(), r * t.sin()]
            })
            .collect();
        StarShape::Polygon { vertices }
    }

    #[test]
    fn areas() {
        let d = StarShape::Disc { radius: 0.7 };
        assert!((d.area() - PI * 0.49).abs() < 1e-15);
        let sq = StarShape::Polygon {
            vertices: vec![[-1.0, -0.5], [1.0, -0.5], [1.0, 0.5], [-1.0, 0.5]],
        };
        assert!((sq.area() - 2.0).abs() < 1e-15);
        let f = sample_fourier();
        let exact = PI * 1.69 * (1.0 + 0.5 * (0.08f64.powi(2) + 0.04f64.powi(2) + 0.02f64.powi(2)));
        assert!(
            (f.area() - exact).abs() < 1e-13 * exact,
            "{} vs {exact}",
            f.area()
        );
        // A fine polygon of the contour agrees too (independent check of the formula).
        let poly = polygon_area(&f.outline(20000));
        assert!((poly - exact).abs() < 1e-6 * exact);
        // The rotated shape has the same area and the rotated radius function.
        let g = f.rotated(0.8);
        assert!((g.area() - f.area()).abs() < 1e-13);
        assert!((g.radius_at(1.5) - f.radius_at(0.7)).abs() < 1e-13);
        let s = star_polygon();
        let sr = s.rotated(0.4);
        assert!((sr.radius_at(0.5) - s.radius_at(0.1)).abs() < 1e-13);
    }

    #[test]
    fn segment_intersection_is_robust_for_collinear_chains() {
        // Nodes along a slanted straight edge: rounding makes them not exactly collinear, but
        // disjoint pieces of the edge must not be reported as touching.
        let (a, b) = ([0.45f64 * 0.3f64.cos(), 0.2], [-0.139_058, -0.427_975]);
        let at = |t: f64| [a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])];
        assert!(segment_intersection(at(0.0), at(0.25), at(0.5), at(0.75)).is_none());
        assert!(segment_intersection(at(0.0), at(0.5), at(0.25), at(0.75)).is_some());
        assert!(segment_intersection([0.0, 0.0], [1.0, 1.0], [0.0, 1.0], [1.0, 0.0]).is_some());
        assert!(segment_intersection([0.0, 0.0], [1.0, 0.0], [0.5, 0.0], [0.5, 1.0]).is_some());
        assert!(segment_intersection([0.0, 0.0], [1.0, 0.0], [0.5, 1e-9], [0.5, 1.0]).is_none());
    }

    #[test]
    fn bounds_of_the_radius() {
        let f = sample_fourier();
        let fine = f.outline(100_000);
        let max = fine.iter().map(|p| norm(*p)).fold(0.0, f64::max);
        let min = fine.iter().map(|p| norm(*p)).fold(f64::MAX, f64::min);
        assert!(f.max_radius() >= max && f.max_radius() < max + 1e-4);
        assert!(f.min_radius() <= min && f.min_radius() > min - 1e-4);
        let s = star_polygon();
        assert!((s.max_radius() - 1.0).abs() < 1e-15);
        // The star's edges are the contour: radius_at on a vertex direction and mid-edge.
        assert!((s.radius_at(0.0) - 1.0).abs() < 1e-14);
        assert!((s.radius_at(PI / 5.0) - 0.45).abs() < 1e-14);
    }

    #[test]
    fn validation() {
        assert!(star_polygon().validate().is_ok());
        assert!(sample_fourier().validate().is_ok());
        // Bow-tie.
        let bow = StarShape::Polygon {
            vertices: vec![[-1.0, -1.0], [1.0, 1.0], [1.0, -1.0], [-1.0, 1.0]],
        };
        let e = bow.validate().unwrap_err().to_string();
        assert!(e.contains("self-intersecting"), "{e}");
        assert!(
            e.contains("edge vertex 0→vertex 1 crosses edge vertex 2→vertex 3"),
            "{e}"
        );
        // A C shape around the origin: simple, but the vertices are not angularly ordered about
        // the origin (the inner arc goes clockwise).
        let mut c = Vec::new();
        for k in 0..=8 {
            let t = 0.5 + (TAU - 1.0) * k as f64 / 8.0;
            c.push([t.cos(), t.sin()]);
        }
        for k in (0..=8).rev() {
            let t = 0.5 + (TAU - 1.0) * k as f64 / 8.0;
            c.push([0.6 * t.cos(), 0.6 * t.sin()]);
        }
        let cshape = StarShape::Polygon { vertices: c };
        let e = cshape.validate().unwrap_err().to_string();
        assert!(e.contains("not star-shaped"), "{e}");
        // Clockwise.
        let cw = StarShape::Polygon {
            vertices: vec![[1.0, 0.0], [0.0, -1.0], [-1.0, 0.0], [0.0, 1.0]],
        };
        assert!(cw.validate().unwrap_err().to_string().contains("clockwise"));
        // r <= 0.
        let neg = StarShape::Fourier {
            r0: 1.0,
            modes: vec![FourierMode {
                n: 3,
                amplitude: 1.2,
                phase: 0.0,
            }],
        };
        let e = neg.validate().unwrap_err().to_string();
        assert!(e.contains("not positive"), "{e}");
        assert!(
            StarShape::Fourier {
                r0: -1.0,
                modes: vec![]
            }
            .validate()
            .is_err()
        );
        assert!(StarShape::Disc { radius: 0.0 }.validate().is_err());
        // NaN.
        assert!(StarShape::Disc { radius: f64::NAN }.validate().is_err());
        let nan = StarShape::Polygon {
            vertices: vec![[1.0, 0.0], [0.0, f64::NAN], [-1.0, -1.0]],
        };
        assert!(nan.validate().unwrap_err().to_string().contains("finite"));
        let nan_mode = StarShape::Fourier {
            r0: 1.0,
            modes: vec![FourierMode {
                n: 2,
                amplitude: f64::NAN,
                phase: 0.0,
            }],
        };
        assert!(nan_mode.validate().is_err());
        // Too few vertices.
        let two = StarShape::Polygon {
            vertices: vec![[1.0, 0.0], [0.0, 1.0]],
        };
        assert!(
            two.validate()
                .unwrap_err()
                .to_string()
                .contains("at least 3")
        );
    }

    #[test]
    fn random_fourier_is_sand_like_and_deterministic() {
        let shapes = sand_like_sample(50, 1.0, 0.2, 42);
        assert_eq!(shapes, sand_like_sample(50, 1.0, 0.2, 42));
        assert_ne!(shapes, sand_like_sample(50, 1.0, 0.2, 43));
        for s in &shapes {
            s.validate().unwrap();
            let StarShape::Fourier { r0, modes } = s else {
                panic!("not Fourier")
            };
            assert!((0.8..=1.2).contains(r0));
            assert_eq!(modes.len(), 7);
            assert!((0.05..=0.1).contains(&modes[0].amplitude));
            assert!(s.min_concave_radius() >= 0.5 * r0 || modes[1].amplitude < 0.05);
            assert!(s.min_radius() > 0.6 * r0);
            assert!(s.max_radius() < 1.4 * r0);
        }
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
        let one = StarShape::random_fourier(2.0, &mut rng, &FourierParams::default());
        one.validate().unwrap();
    }

    #[test]
    fn shape_file_round_trip_and_errors() {
        let dir = std::env::temp_dir().join(format!("sdem-shapes-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("grains.txt");
        let grains = vec![
            ([3.0, -2.0], star_polygon().rotated(0.3)),
            ([10.5, 4.25], sample_fourier()),
        ];
        write_shape_file(&path, &grains, 64).unwrap();
        let back = read_shape_file(&path).unwrap();
        assert_eq!(back.len(), 2);
        for ((c0, s0), (c1, s1)) in grains.iter().zip(&back) {
            let StarShape::Polygon { vertices } = s1 else {
                panic!("a polygon")
            };
            let off = polygon_centroid(&s0.outline(64));
            assert!(
                (c1[0] - c0[0] - off[0]).abs() < 1e-12 && (c1[1] - c0[1] - off[1]).abs() < 1e-12
            );
            for (a, b) in s0.outline(64).iter().zip(vertices) {
                assert!(
                    (a[0] - off[0] - b[0]).abs() < 1e-12 && (a[1] - off[1] - b[1]).abs() < 1e-12
                );
            }
            assert!((s1.area() - polygon_area(&s0.outline(64))).abs() < 1e-12);
        }

        let text = "# test\ngrain a\n0 0\n1 0\n\ngrain b\n0 0\n1 x\n";
        let e = parse_shapes(text, "f.txt").unwrap_err().to_string();
        assert!(e.starts_with("f.txt:8:") && e.contains("`x`"), "{e}");
        let text = "grain a\n0 0\n1 0\n0 1\ngrain b  # two vertices\n0 0\n1 0\n";
        let e = parse_shapes(text, "f.txt").unwrap_err().to_string();
        assert!(
            e.starts_with("f.txt:5:") && e.contains("grain b has 2 vertices"),
            "{e}"
        );
        let text = "0 0\n";
        let e = parse_shapes(text, "f.txt").unwrap_err().to_string();
        assert!(e.starts_with("f.txt:1:") && e.contains("grain"), "{e}");
        let text = "grain\n1 2 3\n";
        assert!(
            parse_shapes(text, "f.txt")
                .unwrap_err()
                .to_string()
                .starts_with("f.txt:2:")
        );
        let text = "grain bow\n0 0\n2 2\n2 0\n0 2\n";
        let e = parse_shapes(text, "f.txt").unwrap_err().to_string();
        assert!(
            e.contains("grain bow") && e.contains("self-intersecting"),
            "{e}"
        );
        assert!(e.contains("line 2") && e.contains("line 4"), "{e}");
        // Clockwise input is accepted (reversed), the closing vertex dropped.
        let text = "grain\n0 0\n0 1\n1 1\n1 0\n0 0\n";
        let g = parse_shapes(text, "f.txt").unwrap();
        assert_eq!(g[0].0, [0.5, 0.5]);
        assert!((g[0].1.area() - 1.0).abs() < 1e-15);
        // Missing file.
        let e = read_shape_file(&dir.join("missing.txt"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("missing.txt"), "{e}");
        std::fs::remove_dir_all(&dir).ok();
    }

    fn check_nodes(shape: &StarShape, spacing: f64, grading: f64) -> GrainNodes {
        let nodes = place_nodes(shape, spacing, grading).unwrap();
        let nb = nodes.boundary_count;
        assert!(nb >= 8);
        for (i, p) in nodes.positions.iter().enumerate() {
            let t = p[1].atan2(p[0]);
            let r = shape.radius_at(t);
            if i < nb {
                assert!(
                    (norm(*p) - r).abs() < 1e-12,
                    "boundary node {i} off the contour"
                );
            } else {
                assert!(norm(*p) < r - 0.3 * spacing, "interior node {i} not inside");
            }
        }
        // Interior nodes are not too close to anything.
        for i in nb..nodes.len() {
            for j in 0..nodes.len() {
                if i != j {
                    let d = norm(sub(nodes.positions[i], nodes.positions[j]));
                    assert!(d >= 0.5 * spacing, "nodes {i} and {j} at {d}");
                }
            }
        }
        // Boundary nodes are CCW (the polygon has positive area and is star-shaped).
        assert!(polygon_defect(nodes.boundary()).is_none());
        nodes
    }

    #[test]
    fn nodes_on_and_inside_smooth_contours() {
        let f = sample_fourier();
        let spacing = 0.15;
        let nodes = check_nodes(&f, spacing, 1.0);
        // Arc-length spacing along the contour within ±20 % (chord = arc to O(s²/R²)).
        let b = nodes.boundary();
        let nb = b.len();
        for i in 0..nb {
            let d = norm(sub(b[(i + 1) % nb], b[i]));
            assert!((d - spacing).abs() < 0.2 * spacing, "boundary gap {d}");
        }
        // Refinement: halving the spacing roughly quadruples the count.
        let fine = check_nodes(&f, spacing / 2.0, 1.0);
        let ratio = fine.len() as f64 / nodes.len() as f64;
        assert!((3.3..4.6).contains(&ratio), "ratio {ratio}");
        // Coarse: too few nodes.
        match place_nodes(&f, 0.9, 1.0) {
            Err(MeshfreeError::TooCoarse { nodes, needed: 21 }) => assert!(nodes < 21),
            other => panic!("expected TooCoarse, got {other:?}"),
        }
        assert!(place_nodes(&f, -1.0, 1.0).is_err());
        assert!(place_nodes(&f, 0.1, f64::NAN).is_err());
    }

    #[test]
    fn disc_nodes_match_disc_nodes() {
        let d = StarShape::Disc { radius: 0.5 };
        let spacing = TAU * 0.5 / 32.0;
        let nodes = check_nodes(&d, spacing, 1.0);
        let reference = DiscNodes::disc(0.5, NodeDensity::new(32)).unwrap();
        assert_eq!(nodes.positions, reference.positions);
        // Not a multiple of 4: the general path, still on the circle.
        let odd = check_nodes(&d, TAU * 0.5 / 30.0, 1.0);
        assert_eq!(odd.boundary_count, 30);
        assert!((odd.len() as f64 / reference.len() as f64 - 1.0).abs() < 0.25);
    }

    #[test]
    fn polygon_corners_are_nodes() {
        let s = star_polygon();
        let nodes = check_nodes(&s, 0.1, 1.0);
        let StarShape::Polygon { vertices } = &s else {
            unreachable!()
        };
        for v in vertices {
            assert!(
                nodes.boundary().iter().any(|p| norm(sub(*p, *v)) < 1e-14),
                "corner {v:?} is not a node"
            );
        }
        // Each edge (length ~0.64) divided evenly: spacing within ±20 %.
        let b = nodes.boundary();
        for i in 0..b.len() {
            let d = norm(sub(b[(i + 1) % b.len()], b[i]));
            assert!((d - 0.1).abs() < 0.2 * 0.1, "gap {d}");
        }
        let fine = check_nodes(&s, 0.05, 1.0);
        let ratio = fine.len() as f64 / nodes.len() as f64;
        assert!((3.0..4.8).contains(&ratio), "ratio {ratio}");
    }

    /// The nodes serve their purpose: RPIM supports built on them reproduce a quadratic field
    /// at every Gauss point of the inside mesh (a badly placed or clustered node set shows up
    /// as a singular or ill-conditioned moment matrix here).
    #[test]
    fn rpim_on_grain_nodes_reproduces_quadratics() {
        use crate::meshfree::discretization::IntegrationMesh;
        use crate::meshfree::rpim::Rpim;
        let mut shapes = sand_like_sample(4, 1.0, 0.2, 5);
        shapes.push(star_polygon());
        for shape in &shapes {
            let nodes = place_nodes(shape, 0.17, 1.0).unwrap();
            let mesh =
                IntegrationMesh::inside_boundary(&nodes.positions, nodes.boundary_count).unwrap();
            let rpim = Rpim::new(&nodes.positions).unwrap();
            let f = |p: [f64; 2]| 1.0 + 2.0 * p[0] - p[1] + p[0] * p[0] + 0.5 * p[0] * p[1];
            for g in &mesh.gauss_points {
                let sf = rpim.shape_functions(g.position).unwrap();
                let (v, dx, dy) = sf.interpolate(|j| f(nodes.positions[j]));
                let [x, y] = g.position;
                assert!((v - f(g.position)).abs() < 1e-8, "value at {x}, {y}");
                assert!((dx - (2.0 + 2.0 * x + 0.5 * y)).abs() < 1e-6);
                assert!((dy - (-1.0 + 0.5 * x)).abs() < 1e-6);
            }
        }
    }

    /// Many shapes and spacings: random star-shaped polygons (irregular angles and radii,
    /// sharp reflex corners) and sand-like grains always give a valid node set whose inside
    /// mesh has the area of the boundary polygon, or a TooCoarse error.
    #[test]
    fn node_placement_sweep() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(77);
        let mut shapes = sand_like_sample(10, 1.0, 0.2, 9);
        for _ in 0..20 {
            let n = 3 + (unit_f64(&mut rng) * 12.0) as usize;
            let mut angles: Vec<f64> = (0..n)
                .map(|k| TAU * (k as f64 + 0.8 * unit_f64(&mut rng)) / n as f64)
                .collect();
            angles.sort_by(f64::total_cmp);
            let vertices = angles
                .iter()
                .map(|t| {
                    let r = 0.4 + 0.8 * unit_f64(&mut rng);
                    [r * t.cos(), r * t.sin()]
                })
                .collect();
            let s = StarShape::Polygon { vertices };
            if s.validate().is_ok() {
                shapes.push(s);
            }
        }
        assert!(shapes.len() > 20);
        let mut placed = 0;
        for shape in &shapes {
            for spacing in [0.08, 0.13, 0.2, 0.3] {
                match place_nodes(shape, spacing, 1.0) {
                    Ok(nodes) => {
                        placed += 1;
                        let mesh =
                            crate::meshfree::discretization::IntegrationMesh::inside_boundary(
                                &nodes.positions,
                                nodes.boundary_count,
                            )
                            .unwrap_or_else(|e| panic!("{shape:?} at {spacing}: {e}"));
                        let exact = polygon_area(nodes.boundary());
                        assert!((mesh.area - exact).abs() < 1e-12 * exact.max(1.0));
                        for p in &nodes.positions[nodes.boundary_count..] {
                            assert!(point_in_polygon(*p, nodes.boundary()));
                        }
                    }
                    Err(MeshfreeError::TooCoarse { nodes, .. }) => assert!(nodes < 21),
                    Err(e) => panic!("{shape:?} at {spacing}: {e}"),
                }
            }
        }
        assert!(placed > 60, "{placed}");
    }

    /// Writes node sets and meshes for a visual check (`cargo test ... dump -- --ignored`).
    #[test]
    #[ignore]
    fn dump_nodes_for_inspection() {
        use crate::meshfree::discretization::IntegrationMesh;
        let mut shapes = sand_like_sample(3, 1.0, 0.2, 5);
        shapes.push(star_polygon());
        shapes.push(StarShape::Disc { radius: 1.0 });
        let mut out = String::new();
        for (k, shape) in shapes.iter().enumerate() {
            let nodes = place_nodes(shape, 0.17, 1.0).unwrap();
            let mesh =
                IntegrationMesh::inside_boundary(&nodes.positions, nodes.boundary_count).unwrap();
            for p in &nodes.positions {
                let _ = writeln!(out, "n {k} {} {}", p[0], p[1]);
            }
            for t in &mesh.triangles {
                let _ = writeln!(out, "t {k} {} {} {}", t[0], t[1], t[2]);
            }
        }
        std::fs::write("/tmp/sdem_nodes.txt", out).unwrap();
    }
}
