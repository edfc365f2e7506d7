//! rovib: classical rotation-vibration dynamics of polyatomic molecules.
pub use rovib_runtime as runtime;
