//! Draws per second of the thermal sampler for water and methane at 300 K (energy cap 0.05
//! hartree): `cargo run --release --features examples --example sampling_rate`.

use std::time::Instant;

use rovib::molecules::{Ch4, H2o};
use rovib::runtime::sample::{Region, Sampler, Thermal};

fn rate<S: Sampler<N>, const N: usize>(name: &str, s: &S) {
    let n = 100_000;
    let start = Instant::now();
    let mut checksum = 0.0;
    for i in 0..n {
        checksum += s.draw(i).expect("draw").q[0];
    }
    let secs = start.elapsed().as_secs_f64();
    println!("{name}: {:.0} draws/s ({n} draws in {secs:.2} s, mean q0 {:.4})", n as f64 / secs, checksum / n as f64);
}

fn main() {
    let t = Instant::now();
    let water = Thermal::new(&H2o, 300.0, &Region::capped(0.05), 1).expect("water sampler");
    println!("water: built in {:.3} s, acceptance {:.3}", t.elapsed().as_secs_f64(), water.acceptance());
    rate("water", &water);
    let t = Instant::now();
    let methane = Thermal::new(&Ch4, 300.0, &Region::capped(0.05), 1).expect("methane sampler");
    println!("ch4: built in {:.3} s, acceptance {:.3}", t.elapsed().as_secs_f64(), methane.acceptance());
    rate("ch4", &methane);
}
