//! Physical constants and unit conversions: `rovib_base::units`, re-exported so that
//! `rovib_runtime::units::...` names the same items the generator uses.

pub use rovib_base::units::*;
