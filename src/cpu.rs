//! The CPU features a binary was built for against the CPU it runs on.
//!
//! A build with `RUSTFLAGS="-C target-cpu=native"` (or another `target-cpu`) may use AVX2 or
//! AVX-512 anywhere (the SIMD lanes of ensembles are built for them, docs/src/howto/ensembles.md, "SIMD lanes"). Run on
//! a CPU without them, such a binary would die of an illegal instruction at some later point;
//! [`missing_features`] lets `main` stop first with a message that says what to do. The
//! detection is the standard library's (`is_x86_feature_detected!`, safe); only the features
//! rovib's vector code uses are checked.

/// The target features this build was compiled for that the running CPU lacks (empty when
/// everything is there, and always on other architectures).
pub fn missing_features() -> Vec<&'static str> {
    #[allow(unused_mut)]
    let mut missing = Vec::new();
    #[cfg(target_arch = "x86_64")]
    {
        macro_rules! check {
            ($($feature:tt),*) => {$(
                if cfg!(target_feature = $feature) && !std::arch::is_x86_feature_detected!($feature) {
                    missing.push($feature);
                }
            )*};
        }
        check!("sse4.1", "avx", "avx2", "fma", "avx512f", "avx512dq", "avx512vl");
    }
    missing
}

/// The error for [`missing_features`], or `None` when the CPU has them all.
pub fn check() -> Option<String> {
    message(&missing_features())
}

/// The error naming `missing` features, or `None` for none.
fn message(missing: &[&str]) -> Option<String> {
    (!missing.is_empty()).then(|| {
        format!(
            "this rovib binary was built for CPU features this CPU lacks ({}); rebuild it on this \
             machine (`cargo build --release`, without RUSTFLAGS=\"-C target-cpu=...\", or with \
             `-C target-cpu=native` here)",
            missing.join(", ")
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The test binary runs on the CPU it was built for (the build's features are a subset of
    /// the host's), so nothing is missing; a missing feature gives a message that names it and
    /// what to do.
    #[test]
    fn the_build_machine_has_its_own_features() {
        assert_eq!(missing_features(), Vec::<&str>::new());
        assert!(check().is_none());
        let m = message(&["avx2", "fma"]).expect("an error");
        assert!(m.contains("(avx2, fma)") && m.contains("rebuild it on this machine"), "{m}");
        assert!(message(&[]).is_none());
    }
}
