//! The `rovib` command line.
fn main() {}
