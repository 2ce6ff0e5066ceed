//! Macroscopic measures of a box sample (SPEC §7).

use crate::boundary::loading::LoadState;
use crate::boundary::walls::{BOTTOM, LEFT, RIGHT, TOP, box_size};
use crate::integration::World;

/// The columns of `macro.csv` that every sdem wrote; the later ones follow in [`Measures::HEADER`]
/// (a macro, so that the headers of older files are spelled once, with the current one).
macro_rules! columns_before_levels {
    () => {
        "step,time,phase,phi,sxx_c,syy_c,p_c,q_c,z,z_nr,kinetic_energy,elastic_energy,inertial_number,strain_rate,box_width,box_height,contacts,capped_contacts"
    };
}

/// One row of `macro.csv`.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Measures {
    pub step: u64,
    pub time: f64,
    pub phase: String,
    /// Sum of current grain areas over the box area.
    pub phi: f64,
    /// Wall stresses, compression positive: mean normal force of two opposite walls over the
    /// current length of those walls.
    pub sxx_c: f64,
    pub syy_c: f64,
    pub p_c: f64,
    pub q_c: f64,
    /// Coordination number 2C/N over grain–grain contacts.
    pub z: f64,
    /// The same without rattlers (grains with fewer than 2 contacts).
    pub z_nr: f64,
    /// The same without the rattlers of the usual frictionless 2D rule (SPEC §7): grains with
    /// fewer than 3 contacts (walls included) removed, the counts redone, until none is removed
    /// (see [`coordination_without_rattlers`]).
    pub z_nr3: f64,
    pub kinetic_energy: f64,
    /// Strain energy of the grains (SPEC §3 laws).
    pub elastic_energy: f64,
    /// Inertial number `rate d_mean sqrt(rho / p_c)` at this step (inf before any load).
    pub inertial_number: f64,
    /// Strain rate of the box, compression positive.
    pub strain_rate: f64,
    pub box_width: f64,
    pub box_height: f64,
    pub contacts: u64,
    pub capped_contacts: u64,
    /// Grains at each model level (Rigid, Volumetric, Full) for the next step.
    pub levels: [u64; 3],
}

impl Measures {
    pub const HEADER: &'static str = concat!(
        columns_before_levels!(),
        ",grains_rigid,grains_volumetric,grains_full,z_nr3"
    );

    /// The header before the `z_nr3` column (macro.csv of sdem before the 3-contact rattler rule).
    pub const HEADER_WITHOUT_Z_NR3: &'static str = concat!(
        columns_before_levels!(),
        ",grains_rigid,grains_volumetric,grains_full"
    );

    /// The header before the level columns (macro.csv of sdem before the adaptive level).
    pub const HEADER_WITHOUT_LEVELS: &'static str = columns_before_levels!();

    /// Wall stresses (in a periodic cell, the cell's contact stresses, compression positive)
    /// and packing fraction only: cheap enough for every step.
    pub fn box_state(world: &World) -> (f64, f64, f64, f64, f64) {
        let (width, height) = box_size(&world.walls);
        let (sxx, syy) = if world.periodic.is_some() {
            let s = &world.totals.cell_stress;
            (-s[0], -s[1])
        } else {
            let f = &world.totals.wall_force;
            (
                0.5 * (f[LEFT] + f[RIGHT]) / height,
                0.5 * (f[BOTTOM] + f[TOP]) / width,
            )
        };
        // A sheared cell keeps the area width × height.
        let phi = world.totals.grain_area / (width * height);
        (phi, sxx, syy, width, height)
    }

    pub fn load_state(world: &World, jammed: bool, mean_diameter: f64) -> LoadState {
        let (phi, sxx, syy, _, _) = Self::box_state(world);
        LoadState {
            phi,
            sxx,
            syy,
            jammed,
            mean_diameter,
            density: world.params.material.density,
            young: world.params.material.young,
            shear_strain: world.periodic.map_or(0.0, |p| p.shear_strain),
        }
    }

    /// The full row, coordination included (a pass over the pairs).
    pub fn of(world: &World, phase: &str, strain_rate: f64, mean_diameter: f64) -> Self {
        let (phi, sxx_c, syy_c, box_width, box_height) = Self::box_state(world);
        let (z, z_nr, z_nr3) = world.coordination();
        let p_c = 0.5 * (sxx_c + syy_c);
        let state = Self::load_state(world, true, mean_diameter);
        Measures {
            step: world.step,
            time: world.time,
            phase: phase.to_string(),
            phi,
            sxx_c,
            syy_c,
            p_c,
            q_c: 0.5 * (sxx_c - syy_c),
            z,
            z_nr,
            z_nr3,
            kinetic_energy: world.kinetic().energy,
            elastic_energy: world.totals.elastic_energy,
            inertial_number: state.inertial_number(strain_rate),
            strain_rate,
            box_width,
            box_height,
            contacts: world.totals.contacts,
            capped_contacts: world.totals.capped_contacts,
            levels: world.totals.level_counts,
        }
    }

    pub fn csv_row(&self) -> String {
        format!(
            "{},{:.9e},{},{:.9},{:.9e},{:.9e},{:.9e},{:.9e},{:.6},{:.6},{:.6e},{:.6e},{:.6e},{:.6e},{:.9},{:.9},{},{},{},{},{},{:.6}",
            self.step,
            self.time,
            self.phase,
            self.phi,
            self.sxx_c,
            self.syy_c,
            self.p_c,
            self.q_c,
            self.z,
            self.z_nr,
            self.kinetic_energy,
            self.elastic_energy,
            self.inertial_number,
            self.strain_rate,
            self.box_width,
            self.box_height,
            self.contacts,
            self.capped_contacts,
            self.levels[0],
            self.levels[1],
            self.levels[2],
            self.z_nr3
        )
    }
}

/// Coordination number without the rattlers of the rule "a grain needs `min_contacts`
/// contacts": every grain with fewer contacts (grains and walls together) is removed, which
/// takes a contact from each of its neighbours, until no grain is removed; the result is
/// `2 C / N` over the grain–grain contacts between the grains left (0 if none is left). With
/// `min_contacts = 3` it is the usual rule for frictionless 2D packings (a grain needs d + 1
/// contacts to be in stable equilibrium).
///
/// `wall_contacts[g]` is the number of walls grain `g` touches; `pairs` the grain–grain
/// contacts, each once.
pub fn coordination_without_rattlers(
    wall_contacts: &[u32],
    pairs: &[(u32, u32)],
    min_contacts: u32,
) -> f64 {
    let n = wall_contacts.len();
    let mut contacts = wall_contacts.to_vec();
    // Neighbour lists in compressed rows: `start[g]..start[g + 1]` of `neighbours`.
    let mut start = vec![0usize; n + 1];
    for &(i, j) in pairs {
        contacts[i as usize] += 1;
        contacts[j as usize] += 1;
        start[i as usize + 1] += 1;
        start[j as usize + 1] += 1;
    }
    for g in 0..n {
        start[g + 1] += start[g];
    }
    let mut fill = start.clone();
    let mut neighbours = vec![0u32; start[n]];
    for &(i, j) in pairs {
        neighbours[fill[i as usize]] = j;
        fill[i as usize] += 1;
        neighbours[fill[j as usize]] = i;
        fill[j as usize] += 1;
    }
    let mut removed = vec![false; n];
    let mut to_remove: Vec<usize> = (0..n).filter(|&g| contacts[g] < min_contacts).collect();
    for &g in &to_remove {
        removed[g] = true;
    }
    while let Some(g) = to_remove.pop() {
        for &other in &neighbours[start[g]..start[g + 1]] {
            let other = other as usize;
            contacts[other] -= 1;
            if !removed[other] && contacts[other] < min_contacts {
                removed[other] = true;
                to_remove.push(other);
            }
        }
    }
    let kept = removed.iter().filter(|&&r| !r).count();
    let kept_contacts = pairs
        .iter()
        .filter(|&&(i, j)| !removed[i as usize] && !removed[j as usize])
        .count();
    if kept > 0 {
        2.0 * kept_contacts as f64 / kept as f64
    } else {
        0.0
    }
}

#[cfg(test)]
mod tests {
    use super::coordination_without_rattlers;

    /// A triangle of grains each touching the other two and one wall: every grain has 3
    /// contacts, none is a rattler, z = 2.
    #[test]
    fn a_braced_triangle_keeps_every_grain() {
        let pairs = [(0, 1), (1, 2), (0, 2)];
        assert_eq!(coordination_without_rattlers(&[1, 1, 1], &pairs, 3), 2.0);
    }

    /// A chain 0-1-2-3 between two walls: the ends have 2 contacts (a wall and a grain), so
    /// they go; then the inner grains have 1 each and go too: the removal cascades to nothing.
    #[test]
    fn a_chain_cascades_to_nothing() {
        let pairs = [(0, 1), (1, 2), (2, 3)];
        assert_eq!(coordination_without_rattlers(&[1, 0, 0, 1], &pairs, 3), 0.0);
        // The 2-contact rule keeps the whole chain: z = 2 x 3 / 4.
        assert_eq!(coordination_without_rattlers(&[1, 0, 0, 1], &pairs, 2), 1.5);
    }

    /// A square of four grains with both diagonals (K4, 3 contacts each) and a fifth grain
    /// touching only grain 0: the fifth goes, grain 0 keeps 3 contacts, z = 2 x 6 / 4 = 3.
    #[test]
    fn a_dangling_grain_goes_and_its_neighbour_stays() {
        let pairs = [(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3), (0, 4)];
        assert_eq!(coordination_without_rattlers(&[0; 5], &pairs, 3), 3.0);
    }
}
