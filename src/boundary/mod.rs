//! Boundaries and loading: rigid walls, the box they form, and the programs that move them
//! (strain-driven isotropic and oedometric compaction, a stress servo) (SPEC §7).

pub mod loading;
pub mod walls;

pub use loading::{LoadingProgram, Phase, StopWhen, StrainRate};
pub use walls::{BOTTOM, LEFT, RIGHT, TOP, Wall, box_walls};
