//! Functions of Cartesian positions, for definitions whose coordinates are declared by kind.
//!
//! From the closed forms `q(x)` of [`crate::zmatrix::coordinate_of_positions`] this builds, in
//! the definition's graph (after [`crate::kinetic::build`], whose variables come first):
//!
//! * `q_k(x)` for every coordinate, from the `3·NA` lab-frame position components (bohr; any
//!   frame and origin, since distances, angles and dihedrals are invariant);
//! * `U(x) = U(q(x))`, the potential with every coordinate replaced by its closed form;
//! * `∂U/∂x_{i,a}`, by symbolic differentiation of `U(x)` (the chain rule
//!   `Σ_k ∂U/∂q_k ∂q_k/∂x`, done by [`crate::diff`] like every other derivative).
//!
//! and the generated functions [`specs`] that evaluate them
//! (`Kinematics::internal_coordinates`, `Molecule::cartesian_potential`,
//! `Molecule::cartesian_potential_gradient`), and [`lane_spec`], the gradient's lane-generic
//! form `Molecule::cartesian_potential_gradient_lanes`.
//!
//! Where a coordinate's closed form is not differentiable in `x` (an angle at exactly 0 or π,
//! a dihedral whose axis atoms are collinear) the generated gradient is not finite; the runtime
//! treats that (a set of measure zero) itself.

use proc_macro2::{Ident, Span, TokenStream};
use quote::quote;

use crate::definition::Definition;
use crate::diff::Differentiator;
use crate::emit::{FunctionSpec, OutputGroup, index};
use crate::expr::{ExprId, Graph, Node};
use crate::zmatrix::{self, Kind};

/// The Cartesian expressions of one molecule.
pub struct CartesianExprs {
    /// Graph variable of position component `(axis, atom)`: `first_var + 3·atom + axis`.
    pub first_var: u32,
    /// Number of atoms.
    pub atoms: usize,
    /// `q_k(x)`, atomic units.
    pub coordinates: Vec<ExprId>,
    /// `U(q(x))`, hartree.
    pub potential: ExprId,
    /// `gradient[atom][axis] = ∂U/∂x`, hartree per bohr.
    pub gradient: Vec<[ExprId; 3]>,
    /// The same with the potential's parameters as inputs, for a definition with
    /// `[potential.parameters]` ([`with_parameters`]).
    pub parametric: Option<ParametricCartesian>,
}

/// `U(q(x), params)` and `∂U/∂x` with the parameters as graph variables: what a scene's
/// `[potential.parameters]` runs with in the Cartesian chart.
pub struct ParametricCartesian {
    /// `U(q(x), params)`, hartree.
    pub potential: ExprId,
    /// `gradient[atom][axis] = ∂U/∂x`, hartree per bohr.
    pub gradient: Vec<[ExprId; 3]>,
    /// The graph variable of parameter 0 (parameter i is `first_var + i`).
    pub first_var: u32,
    /// Number of parameters.
    pub count: usize,
}

/// Adds the parametric Cartesian potential to `c` (call after [`crate::parametric::build`]):
/// the parametric `U(q, params)` with every coordinate replaced by its closed form `q(x)`, and
/// its gradient in x by symbolic differentiation, as [`build`] does for the compiled-in values.
pub fn with_parameters(def: &mut Definition, c: &mut CartesianExprs, p: &crate::parametric::ParametricExprs) {
    let g = &mut def.graph;
    let mut map: Vec<Option<ExprId>> = vec![None; g.var_count()];
    for (k, &e) in c.coordinates.iter().enumerate() {
        map[k] = Some(e);
    }
    let potential = substitute(g, p.potential, &map);
    let mut diff = Differentiator::new();
    let gradient = (0..c.atoms)
        .map(|i| [0, 1, 2].map(|a| diff.derivative(g, potential, c.first_var + (3 * i + a) as u32)))
        .collect();
    c.parametric =
        Some(ParametricCartesian { potential, gradient, first_var: p.first_var, count: def.parameters.len() });
}

/// The graph name of position component `axis` of atom `atom` (not an identifier, so no
/// coordinate name can alias it).
fn var_name(atom: usize, axis: usize) -> String {
    format!("x[{atom}].{}", ["x", "y", "z"][axis])
}

/// The local variable that holds position component `axis` of atom `atom` in generated code.
pub fn ident(atom: usize, axis: usize) -> Ident {
    Ident::new(&format!("x{atom}_{}", ["x", "y", "z"][axis]), Span::call_site())
}

/// Builds the Cartesian expressions for a definition with coordinates by kind, `None` for one
/// with explicit positions. Call after [`crate::kinetic::build`].
pub fn build(def: &mut Definition) -> Option<CartesianExprs> {
    // A potential from source files has no closed form in the positions.
    if def.external.is_some() {
        return None;
    }
    let kinds: Vec<Kind> = def.kinds.clone()?;
    let n = def.coordinates.len();
    let na = def.atoms.len();
    let g = &mut def.graph;
    let first_var = g.var_count() as u32;
    let x: Vec<[ExprId; 3]> = (0..na).map(|i| [0, 1, 2].map(|a| g.var(&var_name(i, a)))).collect();
    let coordinates: Vec<ExprId> = kinds.iter().map(|&k| zmatrix::coordinate_of_positions(g, k, &x)).collect();
    let mut map: Vec<Option<ExprId>> = vec![None; g.var_count()];
    for (k, &e) in coordinates.iter().enumerate().take(n) {
        map[k] = Some(e);
    }
    let potential = substitute(g, def.potential, &map);
    let mut diff = Differentiator::new();
    let gradient =
        (0..na).map(|i| [0, 1, 2].map(|a| diff.derivative(g, potential, first_var + (3 * i + a) as u32))).collect();
    Some(CartesianExprs { first_var, atoms: na, coordinates, potential, gradient, parametric: None })
}

/// `e` with every variable `v` for which `map[v]` is `Some(f)` replaced by `f`.
pub fn substitute(g: &mut Graph, e: ExprId, map: &[Option<ExprId>]) -> ExprId {
    let reachable = g.reachable(&[e]);
    let mut image: Vec<Option<ExprId>> = vec![None; e.index() + 1];
    for i in 0..=e.index() {
        if !reachable[i] {
            continue;
        }
        let m = |id: ExprId| image[id.index()].expect("children come first");
        let id = ExprId::from_index(i);
        image[i] = Some(match g.node(id) {
            Node::Const(_) => id,
            Node::Var(v) => map.get(v as usize).copied().flatten().unwrap_or(id),
            Node::Neg(a) => g.neg(m(a)),
            Node::Add(a, b) => g.add(m(a), m(b)),
            Node::Sub(a, b) => g.sub(m(a), m(b)),
            Node::Mul(a, b) => g.mul(m(a), m(b)),
            Node::Div(a, b) => g.div(m(a), m(b)),
            Node::Powi(a, p) => g.powi(m(a), p),
            Node::Powf(a, b) => g.pow(m(a), m(b)),
            Node::Call(f, a) => g.call(f, m(a)),
            Node::Atan2(y, x) => g.atan2(m(y), m(x)),
            Node::Select(cmp, x, y, a, b) => g.select(cmp, m(x), m(y), m(a), m(b)),
        });
    }
    image[e.index()].expect("the root is reachable")
}

/// The entries `grad[(a, i)]` of a 3 × atoms gradient, one per atom `i` and axis `a`.
fn gradient_entries(gradient: &[[ExprId; 3]]) -> Vec<(TokenStream, ExprId)> {
    gradient
        .iter()
        .enumerate()
        .flat_map(|(i, row)| {
            row.iter().enumerate().map(move |(a, &e)| {
                let (ai, ii) = (index(a), index(i));
                (quote!([(#ai, #ii)]), e)
            })
        })
        .collect()
}

/// `cartesian_potential_gradient_lanes<T: Real>`: the gradient of [`specs`] for `T::LANES`
/// position sets at once, from the same expressions (emit it with `emit::Flavor::Lanes`), with
/// positions and gradient as arrays `x[atom][axis]`.
pub fn lane_spec(c: &CartesianExprs) -> FunctionSpec {
    let nal = index(c.atoms);
    let inputs: Vec<(u32, TokenStream)> = (0..c.atoms)
        .flat_map(|i| {
            (0..3).map(move |a| {
                let (ai, ii) = (index(a), index(i));
                (c.first_var + (3 * i + a) as u32, quote!(x[#ii][#ai]))
            })
        })
        .collect();
    let entries = c
        .gradient
        .iter()
        .enumerate()
        .flat_map(|(i, row)| {
            row.iter().enumerate().map(move |(a, &e)| {
                let (ai, ii) = (index(a), index(i));
                (quote!([#ii][#ai]), e)
            })
        })
        .collect();
    FunctionSpec {
        name: "cartesian_potential_gradient_lanes",
        doc: "[`Molecule::cartesian_potential_gradient`] for `T::LANES` position sets at once (lane-generic,\n\
              branch-free; `x[i]` and `grad[i]` are atom i); returns U."
            .into(),
        signature: quote!(
            fn cartesian_potential_gradient_lanes<T: Real>(
                &self,
                x: &[[T; 3]; #nal],
                grad: &mut [[T; 3]; #nal],
            ) -> Option<T>
        ),
        inputs,
        groups: vec![OutputGroup { target: quote!(grad), entries }],
        ret: Some(c.potential),
        ret_wrap: Some(|t| quote!(Some(#t))),
        barrier: None,
    }
}

/// The generated functions: `internal_coordinates`, `cartesian_potential` and
/// `cartesian_potential_gradient`, all taking `x: &SMatrix<f64, 3, NA>` (column i is atom i).
pub fn specs(c: &CartesianExprs, n: usize, g: &Graph) -> Vec<FunctionSpec> {
    let (nl, nal) = (index(n), index(c.atoms));
    let inputs: Vec<(u32, TokenStream)> = (0..c.atoms)
        .flat_map(|i| {
            (0..3).map(move |a| {
                let (ai, ii) = (index(a), index(i));
                (c.first_var + (3 * i + a) as u32, quote!(x[(#ai, #ii)]))
            })
        })
        .collect();
    let x_ty = quote!(&SMatrix<f64, 3, #nal>);
    let grad_entries = gradient_entries(&c.gradient);
    let mut specs = vec![
        FunctionSpec {
            name: "internal_coordinates",
            doc: "The internal coordinates of Cartesian positions `x` (bohr, column i is atom i, any frame),\n\
                  in closed form: distances, angles in [0, π], dihedrals in (−π, π]. Returns true."
                .into(),
            signature: quote!(fn internal_coordinates(&self, x: #x_ty, q: &mut SVector<f64, #nl>) -> bool),
            inputs: inputs.clone(),
            groups: vec![OutputGroup {
                target: quote!(q),
                entries: c
                    .coordinates
                    .iter()
                    .enumerate()
                    .map(|(k, &e)| {
                        let k = index(k);
                        (quote!([#k]), e)
                    })
                    .collect(),
            }],
            ret: Some(g.one()),
            ret_wrap: Some(|_| quote!(true)),
            barrier: None,
        },
        FunctionSpec {
            name: "cartesian_potential",
            doc: "The potential U(q(x)) in hartree at Cartesian positions `x` (bohr).".into(),
            signature: quote!(fn cartesian_potential(&self, x: #x_ty) -> Option<f64>),
            inputs: inputs.clone(),
            groups: vec![],
            ret: Some(c.potential),
            ret_wrap: Some(|t| quote!(Some(#t))),
            barrier: None,
        },
        FunctionSpec {
            name: "cartesian_potential_gradient",
            doc: "∂U/∂x in hartree per bohr into `grad` (column i is atom i); returns U (hartree).".into(),
            signature: quote!(
                fn cartesian_potential_gradient(&self, x: #x_ty, grad: &mut SMatrix<f64, 3, #nal>) -> Option<f64>
            ),
            inputs: inputs.clone(),
            groups: vec![OutputGroup { target: quote!(grad), entries: grad_entries }],
            ret: Some(c.potential),
            ret_wrap: Some(|t| quote!(Some(#t))),
            barrier: None,
        },
    ];
    if let Some(p) = &c.parametric {
        let mut inputs = inputs;
        inputs.extend((0..p.count).map(|i| {
            let i_lit = index(i);
            (p.first_var + i as u32, quote!(params[#i_lit]))
        }));
        let grad_entries = gradient_entries(&p.gradient);
        specs.push(FunctionSpec {
            name: "cartesian_potential_with",
            doc: "U(q(x)) in hartree at Cartesian positions `x` (bohr) with the parameters `params` (in the order\n\
                  of `parameters()`) instead of the compiled-in values."
                .into(),
            signature: quote!(fn cartesian_potential_with(&self, x: #x_ty, params: &[f64]) -> Option<f64>),
            inputs: inputs.clone(),
            groups: vec![],
            ret: Some(p.potential),
            ret_wrap: Some(|t| quote!(Some(#t))),
            barrier: None,
        });
        specs.push(FunctionSpec {
            name: "cartesian_potential_gradient_with",
            doc: "∂U/∂x (hartree per bohr, column i is atom i) into `grad` with the parameters `params`; returns U."
                .into(),
            signature: quote!(
                fn cartesian_potential_gradient_with(
                    &self,
                    x: #x_ty,
                    params: &[f64],
                    grad: &mut SMatrix<f64, 3, #nal>,
                ) -> Option<f64>
            ),
            inputs,
            groups: vec![OutputGroup { target: quote!(grad), entries: grad_entries }],
            ret: Some(p.potential),
            ret_wrap: Some(|t| quote!(Some(#t))),
            barrier: None,
        });
    }
    specs
}
