//! Macroscopic measures of a box sample (SPEC §7).

use crate::boundary::loading::LoadState;
use crate::boundary::walls::{BOTTOM, LEFT, RIGHT, TOP, box_size};
use crate::integration::World;

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
    pub const HEADER: &'static str = "step,time,phase,phi,sxx_c,syy_c,p_c,q_c,z,z_nr,kinetic_energy,elastic_energy,inertial_number,strain_rate,box_width,box_height,contacts,capped_contacts,grains_rigid,grains_volumetric,grains_full";

    /// The header before the level columns (macro.csv of sdem before the adaptive level).
    pub const HEADER_WITHOUT_LEVELS: &'static str = "step,time,phase,phi,sxx_c,syy_c,p_c,q_c,z,z_nr,kinetic_energy,elastic_energy,inertial_number,strain_rate,box_width,box_height,contacts,capped_contacts";

    /// Wall stresses and packing fraction only: cheap enough for every step.
    pub fn box_state(world: &World) -> (f64, f64, f64, f64, f64) {
        let (width, height) = box_size(&world.walls);
        let f = &world.totals.wall_force;
        let sxx = 0.5 * (f[LEFT] + f[RIGHT]) / height;
        let syy = 0.5 * (f[BOTTOM] + f[TOP]) / width;
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
        }
    }

    /// The full row, coordination included (a pass over the pairs).
    pub fn of(world: &World, phase: &str, strain_rate: f64, mean_diameter: f64) -> Self {
        let (phi, sxx_c, syy_c, box_width, box_height) = Self::box_state(world);
        let (z, z_nr) = world.coordination();
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
            kinetic_energy: world.totals.kinetic_energy,
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
            "{},{:.9e},{},{:.9},{:.9e},{:.9e},{:.9e},{:.9e},{:.6},{:.6},{:.6e},{:.6e},{:.6e},{:.6e},{:.9},{:.9},{},{},{},{},{}",
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
            self.levels[2]
        )
    }
}
