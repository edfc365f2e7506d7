//! Criterion benchmarks of one right-hand-side evaluation per molecule.
fn main() {}
