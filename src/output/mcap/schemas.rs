//! What the log holds on disk: the topics, the ROS 2 `.msg` schemas of the CDR channels, the
//! Foxglove scene schema, and the encoders and decoders of the CDR channels.

use super::cdr::{CdrReader, CdrResult, CdrWriter};
use crate::boundary::walls::Wall;
use crate::integration::World;
use crate::output::frame::{FrameContact, FrameGrain};
use crate::output::measures::Measures;
use glam::DVec2;

/// Version of the channel layout below; stored in the `sdem.run` metadata.
/// 2: `/macro` gained `grains_rigid`, `grains_volumetric`, `grains_full` (adaptive level).
pub const FORMAT_VERSION: &str = "2";

pub const TOPIC_GRAINS: &str = "/grains";
pub const TOPIC_CONTACTS: &str = "/contacts";
pub const TOPIC_WALLS: &str = "/walls";
pub const TOPIC_MACRO: &str = "/macro";
pub const TOPIC_SCENE: &str = "/scene";

pub const SCHEMA_GRAINS: &str = "sdem_msgs/msg/Grains";
pub const SCHEMA_CONTACTS: &str = "sdem_msgs/msg/Contacts";
pub const SCHEMA_WALLS: &str = "sdem_msgs/msg/Walls";
pub const SCHEMA_MACRO: &str = "sdem_msgs/msg/Macro";
pub const SCHEMA_SCENE: &str = "foxglove.SceneUpdate";

/// ROS 2 message definition of `/grains`.
pub const GRAINS_MSG: &str = "\
# sdem_msgs/msg/Grains: every grain at one output interval (sdem trajectory log, format 1).
# Arrays are indexed by grain id, the line order of grains.csv. Units: those of the scenario.
uint64 step
float64 time
float64[] x             # centre
float64[] y
float64[] theta         # rigid rotation (rad)
float64[] eps1          # principal strains: semi-axes R (1 + eps1), R (1 + eps2); tension positive
float64[] eps2
float64[] alpha         # orientation of e1 relative to the grain: e1 is at angle theta + alpha
float64[] radius        # reference radius R
float64[] stress_xx     # Love-Weber stress of the contact forces over the current area,
float64[] stress_yy     # global frame, TENSION positive; mean stress (compression positive)
float64[] stress_xy     # is -(stress_xx + stress_yy) / 2
";

/// The columns of `/contacts` that every log has.
macro_rules! contacts_columns {
    () => {
        "\
# sdem_msgs/msg/Contacts: active grain-grain contacts of the step that ended at this frame.
uint64 step
float64 time
uint32[] first          # grain ids of the pair; the normal points from first to second
uint32[] second
float32[] point_x       # contact point x_c = (P + P')/2, P and P' where the contours cross
float32[] point_y
float32[] normal_x      # unit normal, perpendicular to the chord PP'
float32[] normal_y
float32[] force         # total normal force (<= 0: repulsive); force on first = force * normal
float32[] length        # chord length L_c = |PP'|
"
    };
}

/// ROS 2 message definition of `/contacts`.
pub const CONTACTS_MSG: &str = contacts_columns!();

/// ROS 2 message definition of `/contacts` in the log of a frictional run: [`CONTACTS_MSG`]
/// and the tangential force.
pub const CONTACTS_FRICTION_MSG: &str = concat!(
    contacts_columns!(),
    "float32[] tangential_force # Coulomb friction force on first along t = (-normal_y, normal_x)\n"
);

/// The `/contacts` schema of a log: with the tangential force column for a frictional run.
pub(super) fn contacts_msg(tangential: bool) -> &'static str {
    if tangential {
        CONTACTS_FRICTION_MSG
    } else {
        CONTACTS_MSG
    }
}

/// ROS 2 message definition of `/walls`.
pub const WALLS_MSG: &str = "\
# sdem_msgs/msg/Walls: the rigid walls (infinite lines); for a box: left, right, bottom, top.
uint64 step
float64 time
float64[] point_x       # a point of the wall line
float64[] point_y
float64[] normal_x      # unit normal pointing into the domain
float64[] normal_y
float64[] velocity_x
float64[] velocity_y
";

/// ROS 2 message definition of `/macro`.
pub const MACRO_MSG: &str = "\
# sdem_msgs/msg/Macro: one row of macro.csv (stresses COMPRESSION positive, suffix _c).
uint64 step
float64 time
string phase
float64 phi
float64 sxx_c
float64 syy_c
float64 p_c
float64 q_c
float64 z
float64 z_nr
float64 kinetic_energy
float64 elastic_energy
float64 inertial_number
float64 strain_rate
float64 box_width
float64 box_height
uint64 contacts
uint64 capped_contacts
uint64 grains_rigid
uint64 grains_volumetric
uint64 grains_full
float64 z_nr3
";

/// The subset of Foxglove's `foxglove.SceneUpdate` JSON schema that a `/scene` uses, as a
/// literal: `$what` closes its description, `$defs` are the definitions of primitives it adds
/// (whole lines) and `$triangles` the schema of an entity's `triangles`.
macro_rules! scene_schema {
    ($what:literal, $defs:literal, $triangles:literal) => {
        concat!(
            r##"{
  "title": "foxglove.SceneUpdate",
  "description": "An update to the entities displayed in a 3D scene (subset written by sdem"##,
            $what,
            r##")",
  "type": "object",
  "$defs": {
    "time": {"type": "object", "properties": {"sec": {"type": "integer", "minimum": 0}, "nsec": {"type": "integer", "minimum": 0, "maximum": 999999999}}},
    "vector3": {"type": "object", "properties": {"x": {"type": "number"}, "y": {"type": "number"}, "z": {"type": "number"}}},
    "quaternion": {"type": "object", "properties": {"x": {"type": "number"}, "y": {"type": "number"}, "z": {"type": "number"}, "w": {"type": "number"}}},
    "pose": {"type": "object", "properties": {"position": {"$ref": "#/$defs/vector3"}, "orientation": {"$ref": "#/$defs/quaternion"}}},
    "color": {"type": "object", "properties": {"r": {"type": "number"}, "g": {"type": "number"}, "b": {"type": "number"}, "a": {"type": "number"}}},
    "cylinder": {"title": "foxglove.CylinderPrimitive", "type": "object", "properties": {"pose": {"$ref": "#/$defs/pose"}, "size": {"$ref": "#/$defs/vector3"}, "bottom_scale": {"type": "number"}, "top_scale": {"type": "number"}, "color": {"$ref": "#/$defs/color"}}},
"##,
            $defs,
            r##"    "line": {"title": "foxglove.LinePrimitive", "type": "object", "properties": {"type": {"type": "integer"}, "pose": {"$ref": "#/$defs/pose"}, "thickness": {"type": "number"}, "scale_invariant": {"type": "boolean"}, "points": {"type": "array", "items": {"$ref": "#/$defs/vector3"}}, "color": {"$ref": "#/$defs/color"}, "colors": {"type": "array", "items": {"$ref": "#/$defs/color"}}, "indices": {"type": "array", "items": {"type": "integer", "minimum": 0}}}}
  },
  "properties": {
    "deletions": {"type": "array", "items": {"type": "object"}},
    "entities": {"type": "array", "items": {"title": "foxglove.SceneEntity", "type": "object", "properties": {
      "timestamp": {"$ref": "#/$defs/time"},
      "frame_id": {"type": "string"},
      "id": {"type": "string"},
      "lifetime": {"$ref": "#/$defs/time"},
      "frame_locked": {"type": "boolean"},
      "metadata": {"type": "array", "items": {"type": "object", "properties": {"key": {"type": "string"}, "value": {"type": "string"}}}},
      "arrows": {"type": "array"}, "cubes": {"type": "array"}, "spheres": {"type": "array"},
      "cylinders": {"type": "array", "items": {"$ref": "#/$defs/cylinder"}},
      "lines": {"type": "array", "items": {"$ref": "#/$defs/line"}},
      "triangles": "##,
            $triangles,
            r##", "texts": {"type": "array"}, "models": {"type": "array"}
    }}}
  }
}
"##
        )
    };
}
pub(crate) use scene_schema;

/// The subset of Foxglove's `foxglove.SceneUpdate` JSON schema that `/scene` uses (entities
/// made of cylinders and lines).
pub const SCENE_SCHEMA: &str = scene_schema!(": cylinders and lines", "", r#"{"type": "array"}"#);

pub(super) fn encode_grains(buf: &mut Vec<u8>, world: &World) {
    let g = world.grains();
    let s = &world.grain_stress;
    let n = g.len();
    let mut w = CdrWriter::new(buf);
    w.u64(world.step);
    w.f64(world.time);
    w.f64_seq(n, g.iter().map(|g| g.center.x));
    w.f64_seq(n, g.iter().map(|g| g.center.y));
    w.f64_seq(n, g.iter().map(|g| g.theta));
    w.f64_seq(n, g.iter().map(|g| g.eps1));
    w.f64_seq(n, g.iter().map(|g| g.eps2));
    w.f64_seq(n, g.iter().map(|g| g.alpha));
    w.f64_seq(n, g.iter().map(|g| g.radius));
    w.f64_seq(n, s.iter().map(|s| s.external[0]));
    w.f64_seq(n, s.iter().map(|s| s.external[1]));
    w.f64_seq(n, s.iter().map(|s| s.external[2]));
}

pub(super) fn decode_grains(data: &[u8]) -> CdrResult<(u64, f64, Vec<FrameGrain>)> {
    let mut r = CdrReader::new(data)?;
    let step = r.u64()?;
    let time = r.f64()?;
    let columns: Vec<Vec<f64>> = (0..10).map(|_| r.f64_seq()).collect::<CdrResult<_>>()?;
    let n = columns[0].len();
    if columns.iter().any(|c| c.len() != n) {
        return Err("grain columns of different lengths".into());
    }
    let grains = (0..n)
        .map(|k| FrameGrain {
            center: DVec2::new(columns[0][k], columns[1][k]),
            theta: columns[2][k],
            eps1: columns[3][k],
            eps2: columns[4][k],
            alpha: columns[5][k],
            radius: columns[6][k],
            stress: [columns[7][k], columns[8][k], columns[9][k]],
        })
        .collect();
    Ok((step, time, grains))
}

/// `tangential`: append the tangential force column (a frictional run's log).
pub(super) fn encode_contacts(
    buf: &mut Vec<u8>,
    world: &World,
    contacts: &[FrameContact],
    tangential: bool,
) {
    let n = contacts.len();
    let mut w = CdrWriter::new(buf);
    w.u64(world.step);
    w.f64(world.time);
    w.u32_seq(n, contacts.iter().map(|c| c.first));
    w.u32_seq(n, contacts.iter().map(|c| c.second));
    w.f32_seq(n, contacts.iter().map(|c| c.point.x as f32));
    w.f32_seq(n, contacts.iter().map(|c| c.point.y as f32));
    w.f32_seq(n, contacts.iter().map(|c| c.normal.x as f32));
    w.f32_seq(n, contacts.iter().map(|c| c.normal.y as f32));
    w.f32_seq(n, contacts.iter().map(|c| c.force as f32));
    w.f32_seq(n, contacts.iter().map(|c| c.length as f32));
    if tangential {
        w.f32_seq(n, contacts.iter().map(|c| c.tangential_force as f32));
    }
}

pub(super) fn decode_contacts(data: &[u8]) -> CdrResult<Vec<FrameContact>> {
    let mut r = CdrReader::new(data)?;
    let _step = r.u64()?;
    let _time = r.f64()?;
    let first = r.u32_seq()?;
    let second = r.u32_seq()?;
    let columns: Vec<Vec<f32>> = (0..6).map(|_| r.f32_seq()).collect::<CdrResult<_>>()?;
    // The tangential force column is in the logs of frictional runs only.
    let tangential = if r.remaining() > 0 {
        Some(r.f32_seq()?)
    } else {
        None
    };
    let n = first.len();
    if second.len() != n
        || columns.iter().any(|c| c.len() != n)
        || tangential.as_ref().is_some_and(|t| t.len() != n)
    {
        return Err("contact columns of different lengths".into());
    }
    Ok((0..n)
        .map(|k| FrameContact {
            first: first[k],
            second: second[k],
            point: DVec2::new(columns[0][k] as f64, columns[1][k] as f64),
            normal: DVec2::new(columns[2][k] as f64, columns[3][k] as f64),
            force: columns[4][k] as f64,
            length: columns[5][k] as f64,
            tangential_force: tangential.as_ref().map_or(0.0, |t| t[k] as f64),
        })
        .collect())
}

pub(super) fn encode_walls(buf: &mut Vec<u8>, step: u64, time: f64, walls: &[Wall]) {
    let n = walls.len();
    let mut w = CdrWriter::new(buf);
    w.u64(step);
    w.f64(time);
    w.f64_seq(n, walls.iter().map(|w| w.point.x));
    w.f64_seq(n, walls.iter().map(|w| w.point.y));
    w.f64_seq(n, walls.iter().map(|w| w.normal.x));
    w.f64_seq(n, walls.iter().map(|w| w.normal.y));
    w.f64_seq(n, walls.iter().map(|w| w.velocity.x));
    w.f64_seq(n, walls.iter().map(|w| w.velocity.y));
}

pub(super) fn decode_walls(data: &[u8]) -> CdrResult<Vec<Wall>> {
    let mut r = CdrReader::new(data)?;
    let _step = r.u64()?;
    let _time = r.f64()?;
    let c: Vec<Vec<f64>> = (0..6).map(|_| r.f64_seq()).collect::<CdrResult<_>>()?;
    let n = c[0].len();
    if c.iter().any(|col| col.len() != n) {
        return Err("wall columns of different lengths".into());
    }
    Ok((0..n)
        .map(|k| Wall {
            point: DVec2::new(c[0][k], c[1][k]),
            normal: DVec2::new(c[2][k], c[3][k]),
            velocity: DVec2::new(c[4][k], c[5][k]),
        })
        .collect())
}

pub(super) fn encode_macro(buf: &mut Vec<u8>, m: &Measures) {
    let mut w = CdrWriter::new(buf);
    w.u64(m.step);
    w.f64(m.time);
    w.string(&m.phase);
    for v in [
        m.phi,
        m.sxx_c,
        m.syy_c,
        m.p_c,
        m.q_c,
        m.z,
        m.z_nr,
        m.kinetic_energy,
        m.elastic_energy,
        m.inertial_number,
        m.strain_rate,
        m.box_width,
        m.box_height,
    ] {
        w.f64(v);
    }
    w.u64(m.contacts);
    w.u64(m.capped_contacts);
    for n in m.levels {
        w.u64(n);
    }
    w.f64(m.z_nr3);
}

pub(super) fn decode_macro(data: &[u8]) -> CdrResult<Measures> {
    let mut r = CdrReader::new(data)?;
    Ok(Measures {
        step: r.u64()?,
        time: r.f64()?,
        phase: r.string()?,
        phi: r.f64()?,
        sxx_c: r.f64()?,
        syy_c: r.f64()?,
        p_c: r.f64()?,
        q_c: r.f64()?,
        z: r.f64()?,
        z_nr: r.f64()?,
        kinetic_energy: r.f64()?,
        elastic_energy: r.f64()?,
        inertial_number: r.f64()?,
        strain_rate: r.f64()?,
        box_width: r.f64()?,
        box_height: r.f64()?,
        contacts: r.u64()?,
        capped_contacts: r.u64()?,
        levels: [r.u64()?, r.u64()?, r.u64()?],
        // Logs written before the column end here.
        z_nr3: if r.remaining() > 0 {
            r.f64()?
        } else {
            f64::NAN
        },
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn macro_row_round_trips_with_infinities() {
        let m = Measures {
            step: 12,
            time: 0.25,
            phase: "isotropic".into(),
            phi: 0.8,
            inertial_number: f64::INFINITY,
            contacts: 5,
            ..Default::default()
        };
        let mut buf = Vec::new();
        encode_macro(&mut buf, &m);
        assert_eq!(decode_macro(&buf).unwrap(), m);
        // A message of a log written before z_nr3 ends just before it: read, z_nr3 unknown.
        let old_end = buf.len() - 8;
        let old = decode_macro(&buf[..old_end]).unwrap();
        assert!(old.z_nr3.is_nan());
        assert_eq!(
            Measures {
                z_nr3: m.z_nr3,
                ..old
            },
            m
        );
        // Truncated anywhere else: an error, not a panic.
        for cut in (0..buf.len()).filter(|&cut| cut != old_end) {
            assert!(decode_macro(&buf[..cut]).is_err());
        }
    }
}
