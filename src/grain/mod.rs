//! Grains: the six degrees of freedom, generalized masses (SPEC §2), constitutive laws and the
//! incompressibility correction (SPEC §3, §6).

pub mod adaptive;
pub mod constitutive;
pub mod state;

pub use adaptive::{AdaptiveSettings, GrainLevel};
pub use constitutive::Material;
pub use state::{Grain, ModelLevel};
