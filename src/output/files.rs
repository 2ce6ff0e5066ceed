//! Files a run writes: `macro.csv` (one row per output interval) and `grains.csv` (a state).

use super::measures::Measures;
use crate::grain::Grain;
use crate::integration::{GrainStress, World};
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::Path;

/// Writes `macro.csv`, flushing every row so that nothing is lost if the run dies.
pub struct MacroWriter {
    out: BufWriter<File>,
}

impl MacroWriter {
    pub fn create(path: &Path) -> std::io::Result<Self> {
        Self::create_with_columns(path, &[])
    }

    /// [`MacroWriter::create`] for a solver with its own columns after the common ones (see
    /// [`crate::run::Simulation::EXTRA_COLUMNS`]).
    pub fn create_with_columns(path: &Path, extra: &[&str]) -> std::io::Result<Self> {
        let mut out = BufWriter::new(File::create(path)?);
        writeln!(out, "{}", header(extra))?;
        Ok(Self { out })
    }

    /// Continues a `macro.csv` after its first `rows` data rows: anything after them (rows
    /// written after a checkpoint, a partly written line) is cut off, then rows are appended.
    /// Fails if the file has another header or fewer than `rows` complete rows.
    pub fn resume(path: &Path, rows: u64) -> std::io::Result<Self> {
        Self::resume_upgrading(path, rows, None)
    }

    /// [`MacroWriter::resume`], also accepting a `macro.csv` written before the level columns
    /// when `levels` (the grains at each level of a run without the adaptive level) is given:
    /// its header and kept rows get the level columns. A `macro.csv` written before the
    /// `z_nr3` column gets it too, `nan` in the kept rows (not measured then).
    pub fn resume_upgrading(
        path: &Path,
        rows: u64,
        levels: Option<[u64; 3]>,
    ) -> std::io::Result<Self> {
        Self::resume_inner(path, rows, levels, Measures::HEADER)
    }

    /// [`MacroWriter::resume`] of a `macro.csv` with a solver's own columns (see
    /// [`MacroWriter::create_with_columns`]).
    pub fn resume_with_columns(path: &Path, rows: u64, extra: &[&str]) -> std::io::Result<Self> {
        Self::resume_inner(path, rows, None, &header(extra))
    }

    fn resume_inner(
        path: &Path,
        rows: u64,
        levels: Option<[u64; 3]>,
        header: &str,
    ) -> std::io::Result<Self> {
        let bad = |m: String| std::io::Error::new(std::io::ErrorKind::InvalidData, m);
        let bytes = std::fs::read(path)?;
        let mut end = 0usize;
        let mut lines = 0u64;
        // What the kept rows of an older macro.csv need appended to match the header.
        let mut legacy_fill: Option<String> = None;
        while lines < rows + 1 {
            match bytes[end..].iter().position(|&b| b == b'\n') {
                Some(k) => {
                    let first = &bytes[..end + k];
                    if lines == 0 && first != header.as_bytes() {
                        legacy_fill = match levels {
                            Some(l) if first == Measures::HEADER_WITHOUT_LEVELS.as_bytes() => {
                                Some(format!(",{},{},{},nan", l[0], l[1], l[2]))
                            }
                            _ if header == Measures::HEADER
                                && first == Measures::HEADER_WITHOUT_Z_NR3.as_bytes() =>
                            {
                                Some(",nan".to_string())
                            }
                            _ => {
                                return Err(bad(
                                    "not a macro.csv of this sdem (header differs)".into()
                                ));
                            }
                        };
                    }
                    end += k + 1;
                    lines += 1;
                }
                None => {
                    return Err(bad(format!(
                        "it has {} complete rows",
                        lines.saturating_sub(1)
                    )));
                }
            }
        }
        if let Some(fill) = legacy_fill {
            let text = String::from_utf8_lossy(&bytes[..end]);
            let mut upgraded = String::with_capacity(end + (rows as usize + 1) * fill.len());
            for (k, line) in text.lines().enumerate() {
                if k == 0 {
                    upgraded.push_str(Measures::HEADER);
                } else {
                    upgraded.push_str(line);
                    upgraded.push_str(&fill);
                }
                upgraded.push('\n');
            }
            std::fs::write(path, upgraded)?;
            let file = std::fs::OpenOptions::new().append(true).open(path)?;
            return Ok(Self {
                out: BufWriter::new(file),
            });
        }
        let file = std::fs::OpenOptions::new().write(true).open(path)?;
        file.set_len(end as u64)?;
        let file = std::fs::OpenOptions::new().append(true).open(path)?;
        Ok(Self {
            out: BufWriter::new(file),
        })
    }

    pub fn write(&mut self, row: &Measures) -> std::io::Result<()> {
        self.write_with(row, "")
    }

    /// Writes a row followed by a solver's own columns, `extra` (each value after a comma).
    pub fn write_with(&mut self, row: &Measures, extra: &str) -> std::io::Result<()> {
        writeln!(self.out, "{}{extra}", row.csv_row())?;
        self.out.flush()
    }
}

/// The header line (without its newline) with a solver's own columns after the common ones.
fn header(extra: &[&str]) -> String {
    let mut h = Measures::HEADER.to_string();
    for name in extra {
        h.push(',');
        h.push_str(name);
    }
    h
}

/// One line per grain: its six DoF, radius, Love–Weber stress (tension positive) and contacts.
pub fn write_grains_csv(path: &Path, world: &World) -> std::io::Result<()> {
    write_grain_rows(path, world.grains(), &world.grain_stress)
}

/// [`write_grains_csv`] of given grains and stresses (one row per pair: the shorter list
/// sets the number of rows).
pub fn write_grain_rows(
    path: &Path,
    grains: &[Grain],
    stresses: &[GrainStress],
) -> std::io::Result<()> {
    let mut out = BufWriter::new(File::create(path)?);
    writeln!(
        out,
        "id,x,y,radius,theta,eps1,eps2,alpha,stress_xx,stress_yy,stress_xy,mean_stress_c,contacts"
    )?;
    for (k, (g, s)) in grains.iter().zip(stresses).enumerate() {
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
