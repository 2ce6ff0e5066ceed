//! Contact laws: the normal force as a function of the contact geometry (SPEC §5, paper eq. 55–57)
//! and the contact dashpot (eq. 61).

pub mod friction;
pub mod law;

pub use law::{DomainExit, SecantLaw};
