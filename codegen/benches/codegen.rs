//! Criterion benchmarks of code generation per molecule.
fn main() {}
