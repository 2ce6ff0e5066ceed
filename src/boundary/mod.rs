//! Boundaries and loading: rigid walls, the box they form, and the programs that move them
//! (strain-driven isotropic and oedometric compaction, a stress servo) (SPEC §7); the periodic
//! cell (SPEC §14: its geometry, minimum images and stress; not yet wired into the run loop).

pub mod loading;
pub mod periodic;
pub mod walls;

pub use loading::{LoadingProgram, Phase, StopWhen, StrainRate};
pub use walls::{BOTTOM, LEFT, RIGHT, TOP, Wall, box_walls};
