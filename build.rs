//! Generates Rust for every molecule in `molecules/`.
fn main() {}
