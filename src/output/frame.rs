//! The frame model: what one output interval of a run holds, whoever reads or writes it.
//!
//! A [`Frame`] is built from a running [`World`] ([`Frame::of_world`]) or read back from a
//! trajectory log (`output::mcap::Trajectory::frame`); the MCAP writer and reader, `render`,
//! `plot` and the VTK exporter all speak it, so no output module depends on another.

pub mod outline;

use crate::boundary::walls::Wall;
use crate::geometry::GrainShape;
use crate::grain::Grain;
use crate::integration::World;
use crate::output::measures::Measures;
use glam::DVec2;

/// One grain as logged: its six DoF, radius and Love–Weber stress (tension positive).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct FrameGrain {
    pub center: DVec2,
    pub radius: f64,
    pub theta: f64,
    pub eps1: f64,
    pub eps2: f64,
    pub alpha: f64,
    /// (xx, yy, xy), global frame, tension positive.
    pub stress: [f64; 3],
}

impl FrameGrain {
    /// The grain at rest in this configuration (rates are not logged).
    pub fn grain(&self) -> Grain {
        Grain {
            radius: self.radius,
            center: self.center,
            theta: self.theta,
            eps1: self.eps1,
            eps2: self.eps2,
            alpha: self.alpha,
            ..Default::default()
        }
    }

    pub fn shape(&self) -> GrainShape {
        self.grain().shape()
    }

    /// Mean stress, compression positive: `-(sxx + syy) / 2`.
    pub fn mean_stress_c(&self) -> f64 {
        -0.5 * (self.stress[0] + self.stress[1])
    }
}

/// One active grain–grain contact as logged (single precision on disk).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct FrameContact {
    pub first: u32,
    pub second: u32,
    pub point: DVec2,
    /// From `first` towards `second`.
    pub normal: DVec2,
    /// Total normal force, <= 0 when repulsive; the force on `first` is `force * normal`.
    pub force: f64,
    pub length: f64,
    /// Tangential (friction) force on `first` along `perp(normal)`; zero without friction
    /// (and in a log of a frictionless run, whose `/contacts` has no such column).
    pub tangential_force: f64,
}

/// Everything logged at one output interval.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Frame {
    pub step: u64,
    pub time: f64,
    pub log_time: u64,
    /// The SDEM grains (empty in a meshfree log).
    pub grains: Vec<FrameGrain>,
    /// The meshfree grains as contours (`/contours`); `None` in an SDEM log.
    pub contours: Option<Vec<FrameContour>>,
    pub walls: Vec<Wall>,
    /// Grain–grain contacts (none in a meshfree log).
    pub contacts: Vec<FrameContact>,
    /// The `macro.csv` row of this frame (absent if the log has no `/macro` message for it).
    pub measures: Option<Measures>,
    /// The periodic cell of a run without walls, from its four sides in `walls`; None in a box.
    pub cell: Option<crate::boundary::periodic::PeriodicCell>,
    /// Each SDEM grain's model level (0 rigid, 1 volumetric, 2 full) where known: a frame of a
    /// running world has them; a log does not store them.
    pub levels: Option<Vec<u8>>,
}

impl Frame {
    /// The frame of a running SDEM world: what its log would hold at this step (in full
    /// precision), with each grain's model level.
    pub fn of_world(world: &World, measures: Option<Measures>) -> Self {
        let grains = world
            .grains()
            .iter()
            .zip(&world.grain_stress)
            .map(|(g, s)| FrameGrain {
                center: g.center,
                radius: g.radius,
                theta: g.theta,
                eps1: g.eps1,
                eps2: g.eps2,
                alpha: g.alpha,
                stress: s.external,
            })
            .collect();
        Self {
            step: world.step,
            time: world.time,
            log_time: crate::output::mcap::time_to_ns(world.time),
            grains,
            contours: None,
            walls: world.walls.clone(),
            contacts: active_contacts(world),
            measures,
            cell: world.cell(),
            levels: Some(
                world
                    .levels()
                    .iter()
                    .map(|l| l.level.index() as u8)
                    .collect(),
            ),
        }
    }

    /// The frame of a meshfree state: its grains' contours and the walls.
    pub fn of_contours(
        (step, time): (u64, f64),
        contours: Vec<FrameContour>,
        walls: &[Wall],
        measures: Option<Measures>,
    ) -> Self {
        Self {
            step,
            time,
            log_time: crate::output::mcap::time_to_ns(time),
            contours: Some(contours),
            walls: walls.to_vec(),
            measures,
            ..Default::default()
        }
    }

    /// Number of grains: ellipses, or contours in a meshfree frame.
    pub fn grain_count(&self) -> usize {
        match &self.contours {
            Some(c) => c.len(),
            None => self.grains.len(),
        }
    }

    /// The frame's grains with their contact pairs checked against the grain count.
    pub fn check(&self) -> Result<(), String> {
        let n = self.grain_count() as u32;
        if let Some(c) = self.contacts.iter().find(|c| c.first >= n || c.second >= n) {
            return Err(format!(
                "contact ({}, {}) names a grain beyond the {n} of the frame",
                c.first, c.second
            ));
        }
        Ok(())
    }
}

/// One meshfree grain as logged: its deformed contour and mean stress.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct FrameContour {
    /// Grain id (the line of `grains.csv`).
    pub grain: u32,
    /// Mean Cauchy stress (xx, yy, xy), global frame, tension positive.
    pub stress: [f64; 3],
    /// Mean stress, compression positive: `-(sxx + syy) / 2`.
    pub mean_stress_c: f64,
    /// The boundary nodes, counter-clockwise.
    pub points: Vec<DVec2>,
}

impl FrameContour {
    /// Area and area centroid of the polygon (the shoelace formula, as the solver computes
    /// them for `grains.csv`).
    pub fn area_centroid(&self) -> (f64, DVec2) {
        let p = &self.points;
        let n = p.len();
        let (mut a2, mut cx, mut cy) = (0.0, 0.0, 0.0);
        for k in 0..n {
            let (a, b) = (p[k], p[(k + 1) % n]);
            let cross = a.x * b.y - b.x * a.y;
            a2 += cross;
            cx += (a.x + b.x) * cross;
            cy += (a.y + b.y) * cross;
        }
        (0.5 * a2, DVec2::new(cx / (3.0 * a2), cy / (3.0 * a2)))
    }

    /// Radius of the disc of the same area.
    pub fn equivalent_radius(&self) -> f64 {
        (self.area_centroid().0.abs() / std::f64::consts::PI).sqrt()
    }
}

/// The active contacts of the world's last step, in pair order.
pub fn active_contacts(world: &World) -> Vec<FrameContact> {
    world
        .contacts()
        .map(|([i, j], c, state)| FrameContact {
            first: i,
            second: j,
            point: c.point,
            normal: c.normal,
            force: c.force,
            length: state.contact_length,
            tangential_force: c.tangential_force,
        })
        .collect()
}
