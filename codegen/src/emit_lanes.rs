//! The lane-generic form of the production path's generated functions:
//! `kinetic_and_gradient_lanes` and `potential_gradient_lanes`, generic over
//! `T: rovib_runtime::lanes::Real` (`f64` for one trajectory, a SIMD vector for several).
//!
//! They are emitted from the same expressions, by the same emitter, as their `f64` counterparts
//! `kinetic_and_gradient` and `potential_gradient` ([`crate::template`]), with
//! [`Flavor::Lanes`]: constants become `T::splat(c)` and the outputs are fixed-size arrays
//! (`k.a[j][l]`, `grad[l]`) instead of nalgebra matrices. Every node is the same operation on
//! the same operands: each lane computes the `f64` function's numbers, except that `sin_cos` and
//! `exp` are `T`'s (for the vector types, polynomials within 2 ulp of libm, identical for every
//! lane width: `rovib_runtime::transcendental`). The code has no branches.

use proc_macro2::{Ident, TokenStream};
use quote::quote;

use crate::emit::{self, Barrier, Flavor, FunctionSpec, FunctionStats, OutputGroup, index};
use crate::kinetic::{KineticExprs, KineticSet};

/// `[i][j]`, an array index suffix.
fn pair(i: usize, j: usize) -> TokenStream {
    let (i, j) = (index(i), index(j));
    quote!([#i][#j])
}

fn single(i: usize) -> TokenStream {
    let i = index(i);
    quote!([#i])
}

/// Stores into `KineticLanes { a: [[T; N]; N], coriolis: [[T; N]; 3], inertia: [[T; 3]; 3] }`.
fn kinetic_groups(target: &TokenStream, set: &KineticSet) -> Vec<OutputGroup> {
    let n = set.a.len();
    let a = (0..n).flat_map(|j| (0..n).map(move |l| (j, l))).map(|(j, l)| (pair(j, l), set.a[j][l])).collect();
    let coriolis =
        (0..3).flat_map(|r| (0..n).map(move |l| (r, l))).map(|(r, l)| (pair(r, l), set.coriolis[r][l])).collect();
    let inertia =
        (0..3).flat_map(|r| (0..3).map(move |c| (r, c))).map(|(r, c)| (pair(r, c), set.inertia[r][c])).collect();
    vec![
        OutputGroup { target: quote!(#target.a), entries: a },
        OutputGroup { target: quote!(#target.coriolis), entries: coriolis },
        OutputGroup { target: quote!(#target.inertia), entries: inertia },
    ]
}

/// The two lane-generic functions of one molecule (methods of its `Molecule` impl), and their
/// statistics. `idents` are the graph variables' local names, as for the `f64` functions.
pub(crate) fn lane_functions(
    graph: &crate::expr::Graph,
    e: &KineticExprs,
    idents: &[Ident],
) -> (Vec<TokenStream>, Vec<FunctionStats>) {
    let nc = e.n;
    let n = index(nc);
    let element = |name: TokenStream, k: usize| {
        let i = single(k);
        quote!(#name #i)
    };
    let q_inputs: Vec<(u32, TokenStream)> = (0..nc).map(|k| (k as u32, element(quote!(q), k))).collect();
    let mut velocity_inputs = q_inputs.clone();
    velocity_inputs.extend((0..3).map(|a| ((nc + a) as u32, element(quote!(omega), a))));
    velocity_inputs.extend((0..nc).map(|k| ((nc + 3 + k) as u32, element(quote!(qdot), k))));
    let gradient = |exprs: &[crate::expr::ExprId]| OutputGroup {
        target: quote!(grad),
        entries: exprs.iter().enumerate().map(|(k, &g)| (single(k), g)).collect(),
    };
    let specs = [
        FunctionSpec {
            name: "kinetic_and_gradient_lanes",
            doc: "[`Kinematics::kinetic_and_gradient`] for `T::LANES` states at once (lane-generic, branch-free; the\n\
                  `f64` function's operations, with `T`'s `sin_cos` and `exp`)."
                .into(),
            signature: quote!(
                fn kinetic_and_gradient_lanes<T: Real>(
                    &self,
                    q: &[T; #n],
                    k: &mut KineticLanes<T, #n>,
                    velocities: impl FnOnce(&KineticLanes<T, #n>) -> ([T; 3], [T; #n]),
                    grad: &mut [T; #n],
                ) -> ([T; 3], [T; #n], T)
            ),
            inputs: velocity_inputs,
            groups: {
                let mut groups = kinetic_groups(&quote!(k), &e.kinetic);
                groups.push(gradient(&e.kinetic_gradient));
                groups
            },
            ret: Some(e.kinetic_energy),
            ret_wrap: Some(|t| quote!((omega, qdot, #t))),
            barrier: Some(Barrier {
                groups_before: 3,
                statement: quote!(let (omega, qdot) = velocities(k);),
                late_vars: (nc..2 * nc + 3).map(|v| v as u32).collect(),
            }),
        },
        FunctionSpec {
            name: "potential_gradient_lanes",
            doc: "[`Molecule::potential_gradient`] for `T::LANES` states at once (lane-generic, branch-free).".into(),
            signature: quote!(fn potential_gradient_lanes<T: Real>(&self, q: &[T; #n], grad: &mut [T; #n]) -> T),
            inputs: q_inputs,
            groups: vec![gradient(&e.potential_gradient)],
            ret: Some(e.potential),
            ret_wrap: None,
            barrier: None,
        },
    ];
    specs.iter().map(|spec| emit::emit_function_as(graph, spec, idents, Flavor::Lanes)).unzip()
}

#[cfg(test)]
mod tests {
    use crate::generate_molecule;

    /// The lane functions are emitted, generic, with constants splatted and no `f64` literal or
    /// `fill` left in them.
    #[test]
    fn water_gets_lane_generic_functions() {
        let text = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../molecules/h2o.toml")).unwrap();
        let m = generate_molecule("molecules/h2o.toml", &text).unwrap();
        let start = m.source.find("fn kinetic_and_gradient_lanes<T: Real>").expect("the lane function is emitted");
        let body = &m.source[start..];
        assert!(body.contains("fn potential_gradient_lanes"), "both are emitted");
        // The kinetic lane function is the last item of `impl Kinematics`.
        let end = body.find("\n}\n").expect("the impl ends");
        let lanes = &body[..end];
        assert!(lanes.contains("T::splat("), "constants are splatted");
        assert!(lanes.contains(".sin_cos()"), "sin and cos of one angle in one call");
        assert!(!lanes.contains(".fill("), "no nalgebra fill in lane code");
        assert!(!lanes.contains("f64"), "no f64 in lane code:\n{lanes}");
        assert!(lanes.contains("let (omega, qdot) = velocities(k);"));
    }

    /// A molecule whose `a` gets its centre-of-mass term at run time (propane, 27 coordinates)
    /// gets no lane functions (they would expand that term and not be the `f64` operations):
    /// the runtime's `lanes::available` then sends it down the one-trajectory path.
    #[test]
    fn run_time_centre_of_mass_molecules_get_no_lane_functions() {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/fixtures/alkanes/propane.toml");
        let text = std::fs::read_to_string(path).unwrap();
        let m = generate_molecule("propane.toml", &text).unwrap();
        assert!(m.source.contains("fn kinetic_and_gradient_sparse"), "propane uses the run-time centre of mass");
        assert!(!m.source.contains("_lanes"), "no lane function");
        assert!(!m.source.contains("has_lane_forms"));
        assert!(!m.source.contains("lanes::"), "no unused lane import");
        let water = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../molecules/h2o.toml")).unwrap();
        assert!(generate_molecule("molecules/h2o.toml", &water).unwrap().source.contains("fn has_lane_forms"));
    }
}
