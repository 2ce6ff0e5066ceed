//! Files a run writes: `macro.csv` (one row per output interval) and `grains.csv` (a state).

use super::measures::Measures;
use crate::integration::World;
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::Path;

/// Writes `macro.csv`, flushing every row so that nothing is lost if the run dies.
pub struct MacroWriter {
    out: BufWriter<File>,
}

impl MacroWriter {
    pub fn create(path: &Path) -> std::io::Result<Self> {
        let mut out = BufWriter::new(File::create(path)?);
        writeln!(out, "{}", Measures::HEADER)?;
        Ok(Self { out })
    }

    pub fn write(&mut self, row: &Measures) -> std::io::Result<()> {
        writeln!(self.out, "{}", row.csv_row())?;
        self.out.flush()
    }
}

/// One line per grain: its six DoF, radius, Love–Weber stress (tension positive) and contacts.
pub fn write_grains_csv(path: &Path, world: &World) -> std::io::Result<()> {
    let mut out = BufWriter::new(File::create(path)?);
    writeln!(
        out,
        "id,x,y,radius,theta,eps1,eps2,alpha,stress_xx,stress_yy,stress_xy,mean_stress_c,contacts"
    )?;
    for (k, (g, s)) in world.grains.iter().zip(&world.grain_stress).enumerate() {
        writeln!(
            out,
            "{k},{:.12e},{:.12e},{:.12e},{:.12e},{:.12e},{:.12e},{:.12e},{:.9e},{:.9e},{:.9e},{:.9e},{}",
            g.center.x,
            g.center.y,
            g.radius,
            g.theta,
            g.eps1,
            g.eps2,
            g.alpha,
            s.external[0],
            s.external[1],
            s.external[2],
            -s.mean_external(),
            s.contacts
        )?;
    }
    out.flush()
}
