//! Output: the macroscopic measures of SPEC §7 and the files a run writes.
//!
//! Every reported stress is **compression positive** (suffix `_c`), as in the paper's figures;
//! the per-grain stresses of `grains.csv` are tension positive like everything in the library.

pub mod colour;
pub mod files;
pub mod frame;
pub mod lock;
pub mod mcap;
pub mod measures;
pub mod plot;
pub mod reference;
pub mod render;
pub mod vtk;

pub use files::{MacroWriter, write_grains_csv};
pub use measures::Measures;
