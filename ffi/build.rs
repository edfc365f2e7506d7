//! Compiles the C surfaces in `surfaces/` into the crate (linked statically). Each gets its own
//! symbol prefix through `SURFACE(name)`, so that a shared library built from the same source
//! (which exports the `rovib_surface_*` names of `include/rovib_surface.h`) never clashes.

fn main() {
    println!("cargo::rerun-if-changed=surfaces/arn2_spline.c");
    println!("cargo::rerun-if-changed=include/rovib_surface.h");
    cc::Build::new()
        .file("surfaces/arn2_spline.c")
        .include("include")
        .define("SURFACE(name)", Some("arn2_spline_##name"))
        .flag_if_supported("-std=c99")
        .warnings(true)
        .compile("rovib_surfaces");
    // The C surfaces call libm (exp, pow, sin, cos).
    if std::env::var("CARGO_CFG_UNIX").is_ok() {
        println!("cargo::rustc-link-lib=m");
    }
}
