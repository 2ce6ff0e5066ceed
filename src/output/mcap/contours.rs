//! Meshfree grains in a trajectory log: each grain as the polygon of its boundary field nodes.
//!
//! A meshfree run (`model: Meshfree(...)`) writes `/contours` in place of `/grains` and
//! `/contacts` (its grains are not ellipses and its contacts are node-to-segment pairs, not
//! chords); `/walls`, `/macro` and `/scene` are as in an SDEM log, and the `sdem.run` metadata
//! says `solver=meshfree`. One `/contours` message per frame holds, for every grain in the
//! order of `grains.csv`, its mean Cauchy stress and the current positions of its boundary
//! nodes, counter-clockwise: the deformed contour, exactly the polygon whose area centroid and
//! area `grains.csv` reports. `/scene` draws each contour as a triangle fan from its area
//! centroid filled with the colour of its mean stress, outlined by a line loop.

use super::cdr::{CdrReader, CdrResult, CdrWriter};
use super::scene::{
    IDENTITY_POSE, encode_box, json_line_loop, json_point, length_decimals, scene_grains_start,
    stress_colour,
};
use super::schemas::scene_schema;
use super::writer::{Bodies, RunInfo, WithPreamble, add_channel};
use super::{McapSettings, TrajectoryWriter, WriteError};
use crate::boundary::walls::Wall;
use crate::output::colour::stress_colour_max;
use crate::output::frame::FrameContour;
use crate::output::measures::Measures;
use crate::scenario::Scenario;
use glam::DVec2;
use std::fmt::Write as _;

pub const TOPIC_CONTOURS: &str = "/contours";
pub const SCHEMA_CONTOURS: &str = "sdem_msgs/msg/Contours";

/// ROS 2 message definition of `/contours`.
pub const CONTOURS_MSG: &str = "\
# sdem_msgs/msg/Contours: every grain of a meshfree run at one output interval, as the polygon
# of its boundary field nodes. Per-grain arrays are indexed by grain id, the line order of
# grains.csv; x and y hold the points of all contours, one contour after the other.
uint64 step
float64 time
uint32[] grain          # grain id of each contour
float64[] stress_xx     # mean Cauchy stress over the current grain (its integral over the
float64[] stress_yy     # current area), global frame, TENSION positive
float64[] stress_xy
float64[] mean_stress_c # -(stress_xx + stress_yy) / 2, COMPRESSION positive
uint32[] point_count    # boundary nodes of each contour
float64[] x             # current positions of the boundary nodes, counter-clockwise
float64[] y
";

/// The subset of Foxglove's `foxglove.SceneUpdate` JSON schema that `/scene` of a meshfree
/// log uses (entities made of triangle lists and lines).
pub const CONTOUR_SCENE_SCHEMA: &str = scene_schema!(
    " for meshfree grains: triangles and lines",
    r##"    "triangles": {"title": "foxglove.TriangleListPrimitive", "type": "object", "properties": {"pose": {"$ref": "#/$defs/pose"}, "points": {"type": "array", "items": {"$ref": "#/$defs/vector3"}}, "color": {"$ref": "#/$defs/color"}, "colors": {"type": "array", "items": {"$ref": "#/$defs/color"}}, "indices": {"type": "array", "items": {"type": "integer", "minimum": 0}}}},
"##,
    r##"{"type": "array", "items": {"$ref": "#/$defs/triangles"}}"##
);

/// What the `sdem.run` metadata of a meshfree log says beyond the scenario.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ContourLogInfo {
    pub grains: usize,
    /// Boundary nodes of all grains together.
    pub boundary_nodes: usize,
    /// The time step.
    pub dt: f64,
}

pub(super) fn encode_contours(buf: &mut Vec<u8>, step: u64, time: f64, contours: &[FrameContour]) {
    let n = contours.len();
    let points: usize = contours.iter().map(|c| c.points.len()).sum();
    let mut w = CdrWriter::new(buf);
    w.u64(step);
    w.f64(time);
    w.u32_seq(n, contours.iter().map(|c| c.grain));
    for k in 0..3 {
        w.f64_seq(n, contours.iter().map(|c| c.stress[k]));
    }
    w.f64_seq(n, contours.iter().map(|c| c.mean_stress_c));
    w.u32_seq(n, contours.iter().map(|c| c.points.len() as u32));
    w.f64_seq(
        points,
        contours.iter().flat_map(|c| c.points.iter().map(|p| p.x)),
    );
    w.f64_seq(
        points,
        contours.iter().flat_map(|c| c.points.iter().map(|p| p.y)),
    );
}

pub(super) fn decode_contours(data: &[u8]) -> CdrResult<(u64, f64, Vec<FrameContour>)> {
    let mut r = CdrReader::new(data)?;
    let step = r.u64()?;
    let time = r.f64()?;
    let grain = r.u32_seq()?;
    let columns: Vec<Vec<f64>> = (0..4).map(|_| r.f64_seq()).collect::<CdrResult<_>>()?;
    let counts = r.u32_seq()?;
    let x = r.f64_seq()?;
    let y = r.f64_seq()?;
    let n = grain.len();
    if columns.iter().any(|c| c.len() != n) || counts.len() != n {
        return Err("contour columns of different lengths".into());
    }
    let total: u64 = counts.iter().map(|&c| c as u64).sum();
    if x.len() != y.len() || total != x.len() as u64 {
        return Err(format!(
            "the point counts add up to {total} but the contours hold {} x and {} y",
            x.len(),
            y.len()
        ));
    }
    let mut start = 0;
    let contours = (0..n)
        .map(|k| {
            let end = start + counts[k] as usize;
            let points = (start..end).map(|i| DVec2::new(x[i], y[i])).collect();
            start = end;
            FrameContour {
                grain: grain[k],
                stress: [columns[0][k], columns[1][k], columns[2][k]],
                mean_stress_c: columns[3][k],
                points,
            }
        })
        .collect();
    Ok((step, time, contours))
}

/// The `/scene` message of a meshfree frame: one entity with, per grain, a triangle fan from
/// its area centroid (filled with the colour of its mean stress, viridis over
/// [`stress_colour_max`]) and its outline as a line loop; then the box.
pub(super) fn encode_contour_scene(
    out: &mut String,
    step: u64,
    contours: &[FrameContour],
    walls: &[Wall],
    log_time: u64,
) {
    out.clear();
    let radii: Vec<f64> = contours.iter().map(|c| c.equivalent_radius()).collect();
    let mean_radius = radii.iter().sum::<f64>() / radii.len().max(1) as f64;
    let decimals = length_decimals(radii.iter().copied().fold(f64::INFINITY, f64::min));
    let means: Vec<f64> = contours.iter().map(|c| c.mean_stress_c).collect();
    let top = stress_colour_max(&means);

    scene_grains_start(out, log_time, top, step);
    out.push_str(",{\"key\":\"solver\",\"value\":\"meshfree\"}");
    out.push_str("],\"arrows\":[],\"cubes\":[],\"spheres\":[],\"cylinders\":[],\"lines\":[");
    // Outlines: a line loop per grain.
    for (k, c) in contours.iter().enumerate() {
        if k > 0 {
            out.push(',');
        }
        json_line_loop(out, &c.points, 0.03 * mean_radius, decimals);
    }
    out.push_str("],\"triangles\":[");
    // Fills: a fan from the area centroid (point 0) over the contour's edges.
    for (k, c) in contours.iter().enumerate() {
        if k > 0 {
            out.push(',');
        }
        let [r, g, b] = stress_colour(c.mean_stress_c, top);
        out.push('{');
        out.push_str(IDENTITY_POSE);
        out.push_str(",\"points\":[");
        json_point(out, c.area_centroid().1, decimals);
        for &p in &c.points {
            out.push(',');
            json_point(out, p, decimals);
        }
        let _ = write!(
            out,
            "],\"color\":{{\"r\":{:.3},\"g\":{:.3},\"b\":{:.3},\"a\":1}},\"colors\":[],\"indices\":[",
            r as f64 / 255.0,
            g as f64 / 255.0,
            b as f64 / 255.0
        );
        let n = c.points.len();
        for i in 0..n {
            if i > 0 {
                out.push(',');
            }
            let _ = write!(out, "0,{},{}", i + 1, (i + 1) % n + 1);
        }
        out.push_str("]}");
    }
    out.push_str("],\"texts\":[],\"models\":[]}");
    encode_box(out, walls, log_time, mean_radius, decimals);
    out.push_str("]}");
}

impl TrajectoryWriter {
    /// Creates the log of a meshfree run: header, the channels `/contours`, `/walls`, `/macro`
    /// and `/scene`, the scenario attachment and the `sdem.run` metadata (with
    /// `solver=meshfree`). Frames go in with [`TrajectoryWriter::write_contour_frame`].
    pub fn create_contours(
        settings: &McapSettings,
        scenario: &Scenario,
        info: &ContourLogInfo,
    ) -> Result<Self, WriteError> {
        Ok(Self::create_contours_with_preamble(settings, scenario, info)?.0)
    }

    /// [`TrajectoryWriter::create_contours`], also returning the `sdem.run` metadata and the
    /// scenario attachment it wrote.
    pub(super) fn create_contours_with_preamble(
        settings: &McapSettings,
        scenario: &Scenario,
        info: &ContourLogInfo,
    ) -> Result<WithPreamble, WriteError> {
        let info = RunInfo {
            grains: info.grains,
            material: &scenario.material,
            model: format!("{:?}", scenario.model),
            dt: info.dt,
            stress_sign: "/contours: stress_* tension positive, mean_stress_c compression positive; \
                 /macro: compression positive",
            extra: vec![
                ("solver", "meshfree".to_string()),
                ("boundary_nodes", info.boundary_nodes.to_string()),
            ],
        };
        Self::create_log(
            settings,
            scenario,
            CONTOUR_SCENE_SCHEMA,
            info,
            |inner, path| {
                let contours = add_channel(
                    inner,
                    path,
                    TOPIC_CONTOURS,
                    SCHEMA_CONTOURS,
                    "ros2msg",
                    CONTOURS_MSG,
                    "cdr",
                )?;
                Ok(Bodies::Contours { contours })
            },
        )
    }

    /// Logs a meshfree state: its grains' contours, the walls and the `macro.csv` row, at
    /// simulated time `time` after `step` steps (and `/scene` on its interval).
    pub fn write_contour_frame(
        &mut self,
        step: u64,
        time: f64,
        contours: &[FrameContour],
        walls: &[Wall],
        row: &Measures,
    ) -> Result<(), WriteError> {
        let Bodies::Contours { contours: channel } = self.bodies else {
            return Err(self.io_error(std::io::Error::other(
                "meshfree contours cannot go into a log of SDEM grains",
            )));
        };
        let log_time = self.next_log_time(time);
        let mut buf = std::mem::take(&mut self.buf);
        encode_contours(&mut buf, step, time, contours);
        self.put(channel, log_time, &buf)?;
        self.finish_frame(buf, log_time, (step, time), walls, row, |text| {
            encode_contour_scene(text, step, contours, walls, log_time)
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn square(grain: u32, at: DVec2, side: f64) -> FrameContour {
        FrameContour {
            grain,
            stress: [-1.0, -3.0, 0.5],
            mean_stress_c: 2.0,
            points: [(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)]
                .iter()
                .map(|&(x, y)| at + side * DVec2::new(x, y))
                .collect(),
        }
    }

    #[test]
    fn contours_round_trip_and_truncations_are_errors() {
        let contours = vec![
            square(0, DVec2::ZERO, 1.0),
            FrameContour {
                points: vec![
                    DVec2::new(3.0, 0.0),
                    DVec2::new(4.0, 0.0),
                    DVec2::new(3.5, 1.0),
                ],
                ..square(1, DVec2::ZERO, 1.0)
            },
        ];
        let mut buf = Vec::new();
        encode_contours(&mut buf, 7, 0.25, &contours);
        let (step, time, back) = decode_contours(&buf).unwrap();
        assert_eq!((step, time), (7, 0.25));
        assert_eq!(back, contours);
        for cut in 0..buf.len() {
            assert!(decode_contours(&buf[..cut]).is_err(), "{cut}");
        }
    }

    #[test]
    fn area_centroid_of_a_square() {
        let (a, c) = square(0, DVec2::new(2.0, 1.0), 2.0).area_centroid();
        assert!((a - 4.0).abs() < 1e-12 && (c - DVec2::new(3.0, 2.0)).length() < 1e-12);
    }

    #[test]
    fn the_scene_is_json_with_a_fan_and_a_loop_per_grain() {
        let contours = vec![square(0, DVec2::ZERO, 1.0), square(1, DVec2::X * 2.0, 1.0)];
        let walls = crate::boundary::walls::box_walls(0.0, 4.0, 0.0, 2.0);
        let mut text = String::new();
        encode_contour_scene(&mut text, 3, &contours, &walls, 1_500_000_000);
        // Balanced brackets outside strings (the text has no escaped quotes).
        let mut depth = 0i32;
        let mut in_string = false;
        for ch in text.chars() {
            match ch {
                '"' => in_string = !in_string,
                '{' | '[' if !in_string => depth += 1,
                '}' | ']' if !in_string => {
                    depth -= 1;
                    assert!(depth >= 0, "{text}");
                }
                _ => {}
            }
        }
        assert_eq!(depth, 0, "{text}");
        // Two outlines and the box as line loops, two fans of four triangles each.
        assert_eq!(text.matches("{\"type\":1,").count(), 3, "{text}");
        assert_eq!(
            text.matches("\"indices\":[0,1,2,0,2,3,0,3,4,0,4,1]")
                .count(),
            2,
            "{text}"
        );
        assert!(text.contains("\"id\":\"box\""));
        assert!(
            text.contains("{\"x\":0.5000,\"y\":0.5000,\"z\":0}"),
            "{text}"
        );
    }
}
