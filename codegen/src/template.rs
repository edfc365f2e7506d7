//! What a generated molecule file contains: the `Molecule` impl around the emitted functions,
//! the atom and coordinate tables, and the `molecules.rs` registry that declares every molecule.
//!
//! The pipeline before this (definition → parse → expr → diff → kinetic) builds the expressions
//! and [`crate::emit`] turns each into a function body; this module decides which functions
//! exist, with which signatures, and what surrounds them.

use proc_macro2::{Ident, Span, TokenStream};
use quote::quote;

use crate::GeneratedMolecule;
use crate::cartesian::CartesianExprs;
use crate::definition::Definition;
use crate::dipole::DipoleExprs;
use crate::emit::{self, Barrier, FunctionSpec, FunctionStats, OutputGroup, doc_lines, index};
use crate::expr;
use crate::kinetic::{KineticExprs, KineticSet, OMEGA_NAMES};
use crate::names::{self, type_name};
use crate::parametric::ParametricExprs;
use crate::units::{AngleUnit, CoordinateUnit, DALTON_IN_ELECTRON_MASSES, LengthUnit};

/// Local variable names for the graph's variables, in variable order: the coordinates, ω, then
/// the velocities, mangled so that no user name can clash with anything (see [`crate::names`]).
fn var_idents(def: &Definition) -> Vec<Ident> {
    let coordinate = |(k, c): (usize, &crate::definition::CoordinateDef)| names::coordinate_ident(k, &c.name);
    let velocity = |(k, c): (usize, &crate::definition::CoordinateDef)| names::velocity_ident(k, &c.name);
    let mut idents: Vec<Ident> =
        def.coordinates.iter().enumerate().map(coordinate).map(|n| Ident::new(&n, Span::call_site())).collect();
    idents.extend(OMEGA_NAMES.iter().map(|n| Ident::new(n, Span::call_site())));
    idents.extend(def.coordinates.iter().enumerate().map(velocity).map(|n| Ident::new(&n, Span::call_site())));
    idents
}

/// The generated file of molecule `name` in `OUT_DIR`; the prefix keeps it apart from the
/// registry `molecules.rs` whatever the molecule is called.
pub fn file_name(name: &str) -> String {
    format!("molecule_{name}.rs")
}

fn float(x: f64) -> TokenStream {
    let lit: proc_macro2::Literal = format!("{:?}", x.abs()).parse().expect("finite");
    if x.is_sign_negative() { quote!(-#lit) } else { quote!(#lit) }
}

/// A range bound: a finite number, or ±infinity by name.
fn bound(x: f64) -> TokenStream {
    match x {
        f64::INFINITY => quote!(f64::INFINITY),
        f64::NEG_INFINITY => quote!(f64::NEG_INFINITY),
        x => float(x),
    }
}

fn unit_tokens(u: CoordinateUnit) -> TokenStream {
    match u {
        CoordinateUnit::Length(LengthUnit::Bohr) => quote!(CoordinateUnit::Length(LengthUnit::Bohr)),
        CoordinateUnit::Length(LengthUnit::Angstrom) => quote!(CoordinateUnit::Length(LengthUnit::Angstrom)),
        CoordinateUnit::Angle(AngleUnit::Rad) => quote!(CoordinateUnit::Angle(AngleUnit::Rad)),
        CoordinateUnit::Angle(AngleUnit::Deg) => quote!(CoordinateUnit::Angle(AngleUnit::Deg)),
    }
}

/// `base[i]`, or `[i]` for an empty base.
fn ix(base: TokenStream, i: usize) -> TokenStream {
    let i = index(i);
    quote!(#base[#i])
}

/// `[(i, j)]`, a matrix index suffix.
fn pair(i: usize, j: usize) -> TokenStream {
    let (i, j) = (index(i), index(j));
    quote!([(#i, #j)])
}

fn kinetic_groups(target: &TokenStream, set: &KineticSet) -> Vec<OutputGroup> {
    let n = set.a.len();
    let mut a = Vec::new();
    for (j, row) in set.a.iter().enumerate() {
        for (k, &e) in row.iter().enumerate() {
            a.push((pair(j, k), e));
        }
    }
    let mut coriolis = Vec::new();
    for (axis, row) in set.coriolis.iter().enumerate() {
        for (k, &e) in row.iter().enumerate().take(n) {
            coriolis.push((pair(axis, k), e));
        }
    }
    let mut inertia = Vec::new();
    for (p, row) in set.inertia.iter().enumerate() {
        for (q, &e) in row.iter().enumerate() {
            inertia.push((pair(p, q), e));
        }
    }
    vec![
        OutputGroup { target: quote!(#target.a), entries: a },
        OutputGroup { target: quote!(#target.coriolis), entries: coriolis },
        OutputGroup { target: quote!(#target.inertia), entries: inertia },
    ]
}

/// What every part of a generated molecule needs: the definition, its expressions, sizes, the
/// graph variables' local names and the inputs of the functions of q and of (q, ω, q̇).
struct Parts<'a> {
    def: &'a Definition,
    e: &'a KineticExprs,
    /// `N` and `NA` as literals.
    n: proc_macro2::Literal,
    na: proc_macro2::Literal,
    /// `&SVector<f64, N>`.
    q_ty: TokenStream,
    idents: Vec<Ident>,
    q_inputs: Vec<(u32, TokenStream)>,
    velocity_inputs: Vec<(u32, TokenStream)>,
}

impl<'a> Parts<'a> {
    fn new(
        def: &'a Definition,
        e: &'a KineticExprs,
        cartesian: Option<&CartesianExprs>,
        parametric: Option<&ParametricExprs>,
    ) -> Self {
        let (n, na) = (index(e.n), index(def.atoms.len()));
        let mut idents = var_idents(def);
        if let Some(c) = cartesian {
            // The Cartesian position variables come after the velocities (see `crate::cartesian`).
            assert_eq!(idents.len(), c.first_var as usize, "position variables follow the velocities");
            idents.extend((0..c.atoms).flat_map(|i| (0..3).map(move |a| crate::cartesian::ident(i, a))));
        }
        if let Some(p) = parametric {
            // Parameter i is graph variable `first_var + i`, bound to `param{i}`.
            while idents.len() < p.first_var as usize {
                idents.push(Ident::new(&format!("unused{}", idents.len()), Span::call_site()));
            }
            idents.extend((0..def.parameters.len()).map(|i| Ident::new(&format!("param{i}"), Span::call_site())));
        }
        let nc = e.n;
        let q_inputs: Vec<(u32, TokenStream)> = (0..nc).map(|k| (k as u32, ix(quote!(q), k))).collect();
        let mut velocity_inputs = q_inputs.clone();
        velocity_inputs.extend((0..3).map(|a| ((nc + a) as u32, ix(quote!(omega), a))));
        velocity_inputs.extend((0..nc).map(|k| ((nc + 3 + k) as u32, ix(quote!(qdot), k))));
        let q_ty = quote!(&SVector<f64, #n>);
        Self { def, e, n, na, q_ty, idents, q_inputs, velocity_inputs }
    }

    /// The functions of `specs`, their statistics appended to `stats`.
    fn emit(&self, specs: &[FunctionSpec], stats: &mut Vec<FunctionStats>) -> Vec<TokenStream> {
        specs
            .iter()
            .map(|spec| {
                let (tokens, s) = emit::emit_function(&self.def.graph, spec, &self.idents);
                stats.push(s);
                tokens
            })
            .collect()
    }

    /// Whether the lane-generic functions are emitted. Not for a molecule whose `a` gets its
    /// centre-of-mass term at run time: its lane functions would have to expand that term (the
    /// code the sparse form avoids) and would not be the `f64` functions' operations, so such a
    /// molecule keeps the traits' lane-by-lane defaults and `has_lane_forms() == false`, and the
    /// runtime integrates it one trajectory at a time.
    fn lanes(&self) -> bool {
        self.e.centre_of_mass_at_run_time.is_none()
    }

    /// The lane-generic `kinetic_and_gradient_lanes` and `potential_gradient_lanes` (the same
    /// operations as their `f64` counterparts, so their statistics are not counted again).
    fn lane_functions(&self) -> (TokenStream, TokenStream) {
        let (functions, _) = crate::emit_lanes::lane_functions(&self.def.graph, self.e, &self.idents);
        let [kinetic, potential]: [TokenStream; 2] = functions.try_into().expect("a kinetic and a potential function");
        (kinetic, potential)
    }
}

/// `target[k] = g_k` for every entry of a gradient.
fn gradient_group(target: TokenStream, gradient: &[expr::ExprId]) -> OutputGroup {
    OutputGroup { target, entries: gradient.iter().enumerate().map(|(k, &g)| (ix(quote!(), k), g)).collect() }
}

/// `target[(axis, atom)]` for every atom's position (or derivative) `rows[atom][axis]`.
fn positions_group(target: TokenStream, rows: &[[expr::ExprId; 3]]) -> OutputGroup {
    let mut entries = Vec::new();
    for (atom, r) in rows.iter().enumerate() {
        for (axis, &c) in r.iter().enumerate() {
            entries.push((pair(axis, atom), c));
        }
    }
    OutputGroup { target, entries }
}

/// The items of one generated molecule file, and the statistics of its functions: the unit
/// struct, its `Kinematics`, `Molecule` and (with a `[dipole]` table) `Dipole` impls.
pub(crate) fn molecule_items(
    def: &Definition,
    e: &KineticExprs,
    cartesian: Option<&CartesianExprs>,
    parametric: Option<&ParametricExprs>,
    dipole: Option<&DipoleExprs>,
) -> (TokenStream, Vec<FunctionStats>) {
    let parts = Parts::new(def, e, cartesian, parametric);
    let (n, na) = (&parts.n, &parts.na);
    let ty = Ident::new(&type_name(&def.name), Span::call_site());
    let mut stats = Vec::new();
    let (inherent_functions, centre_of_mass_wrappers) = centre_of_mass_items(&parts, &mut stats);
    let kinematics = kinematics_impl(&parts, cartesian, centre_of_mass_wrappers, &mut stats);
    let molecule = molecule_impl(&parts, cartesian, parametric, dipole.is_some(), &mut stats);
    let dipole_impl = dipole.map(|d| dipole_impl(&parts, d, &mut stats)).unwrap_or_default();
    // `stats` lists the trait functions before the inherent ones.
    let inherent_stats = stats.drain(..inherent_functions.len()).collect::<Vec<_>>();
    stats.extend(inherent_stats);

    let doc = molecule_doc(def);
    // Import only the unit types the coordinate table names, so no import is unused.
    let mut unit_names: Vec<&str> = Vec::new();
    for c in &def.coordinates {
        unit_names.push("CoordinateUnit");
        unit_names.push(match c.unit {
            CoordinateUnit::Length(_) => "LengthUnit",
            CoordinateUnit::Angle(_) => "AngleUnit",
        });
    }
    unit_names.sort_unstable();
    unit_names.dedup();
    let unit_idents = unit_names.iter().map(|n| Ident::new(n, Span::call_site()));
    let unit_imports =
        if unit_names.is_empty() { quote!() } else { quote!(use ::rovib_runtime::units::{#(#unit_idents),*};) };
    let lane_imports = if parts.lanes() {
        quote!(
            use ::rovib_runtime::lanes::{KineticLanes, Real};
        )
    } else {
        quote!()
    };
    let dipole_import = if dipole.is_some() {
        quote!(
            use ::rovib_runtime::surface::Dipole;
        )
    } else {
        quote!()
    };
    let external_module = match &def.external {
        Some(x) => crate::external::items(x, &def.name, e.n, parts.lanes()).0,
        None => quote!(),
    };
    let items = quote! {
        use ::rovib_runtime::nalgebra::{SMatrix, SVector, Vector3};
        #unit_imports
        use ::rovib_runtime::{Atom, Coordinate, Kinematics, KineticMatrices, Molecule};
        #lane_imports
        #dipole_import

        #external_module

        #doc
        #[derive(Copy, Clone, Debug, Default, PartialEq, Eq)]
        pub struct #ty;

        impl #ty {
            /// Number of internal coordinates.
            pub const N: usize = #n;
            /// Number of atoms.
            pub const NA: usize = #na;

            #(#inherent_functions)*
        }

        impl Kinematics<#n, #na> for #ty {
            #kinematics
        }

        impl Molecule<#n, #na> for #ty {
            #molecule
        }

        #dipole_impl
    };
    (items, stats)
}

/// The generated type's documentation: the definition's description, its file, atoms and
/// coordinates.
fn molecule_doc(def: &Definition) -> TokenStream {
    let path = &def.path;
    let labels: Vec<&str> = def.atoms.iter().map(|a| a.label.as_str()).collect();
    let coord_names: Vec<&str> = def.coordinates.iter().map(|c| c.name.as_str()).collect();
    let doc = if def.description.is_empty() { def.name.clone() } else { def.description.clone() };
    let doc = format!(
        "{doc}\n\nGenerated from `{path}`: {na} atoms ({}), {nc} internal coordinates ({}).",
        labels.join(", "),
        if coord_names.is_empty() { "rigid".to_owned() } else { coord_names.join(", ") },
        na = def.atoms.len(),
        nc = def.coordinates.len(),
    );
    doc_lines(&doc)
}

/// The body of `impl Kinematics`: the atom and coordinate tables, the positions, their Jacobian,
/// the kinetic matrices and ∂T/∂q (with `centre_of_mass_wrappers` in place of the last two for
/// a large molecule), the closed-form internal coordinates of Cartesian positions, the symbolic
/// kinetic Jacobian on request, and the lane form.
fn kinematics_impl(
    parts: &Parts,
    cartesian: Option<&CartesianExprs>,
    centre_of_mass_wrappers: TokenStream,
    stats: &mut Vec<FunctionStats>,
) -> TokenStream {
    let (def, n, na) = (parts.def, &parts.n, &parts.na);
    let functions = parts.emit(&kinematics_specs(parts, cartesian), stats);
    let lanes = if parts.lanes() { parts.lane_functions().0 } else { quote!() };
    let (atoms, coordinates) = (atom_table(def), coordinate_table(def));
    let (name, path) = (&def.name, &def.path);
    quote! {
        fn name(&self) -> &'static str {
            #name
        }

        fn source(&self) -> &'static str {
            #path
        }

        fn atoms(&self) -> [Atom; #na] {
            [#(#atoms),*]
        }

        fn coordinates(&self) -> [Coordinate; #n] {
            [#(#coordinates),*]
        }

        #(#functions)*

        #lanes

        #centre_of_mass_wrappers
    }
}

/// The generated functions of `impl Kinematics`, in the order they are emitted: the positions
/// and their Jacobian, the kinetic matrices (not for a large molecule), ∂T/∂q, both at once (not
/// for a large molecule), the internal coordinates of Cartesian positions when the molecule has
/// a Cartesian chart, and the symbolic kinetic Jacobian on request.
fn kinematics_specs(parts: &Parts, cartesian: Option<&CartesianExprs>) -> Vec<FunctionSpec> {
    let (def, e, n, na, q_ty) = (parts.def, parts.e, &parts.n, &parts.na, &parts.q_ty);
    let nc = e.n;
    let mut specs = vec![
        FunctionSpec {
            name: "positions",
            doc: "Body-frame positions R_i(q) in bohr (column i is atom i), centre of mass at the origin.".into(),
            signature: quote!(fn positions(&self, q: #q_ty, r: &mut SMatrix<f64, 3, #na>)),
            inputs: parts.q_inputs.clone(),
            groups: vec![positions_group(quote!(r), &e.positions)],
            ret: None,
            ret_wrap: None,
            barrier: None,
        },
        FunctionSpec {
            name: "positions_jacobian",
            doc: "`dr[k]` = ∂R/∂q_k, bohr per unit of q_k.".into(),
            signature: quote!(fn positions_jacobian(&self, q: #q_ty, dr: &mut [SMatrix<f64, 3, #na>; #n])),
            inputs: parts.q_inputs.clone(),
            groups: e.jacobian.iter().enumerate().map(|(k, rows)| positions_group(ix(quote!(dr), k), rows)).collect(),
            ret: None,
            ret_wrap: None,
            barrier: None,
        },
    ];
    // Large molecules: `kinetic` and `kinetic_and_gradient` are the wrappers of
    // `centre_of_mass_items` instead.
    if e.centre_of_mass_at_run_time.is_none() {
        specs.push(FunctionSpec {
            name: "kinetic",
            doc: "The kinetic matrices a, A (coriolis) and I at q.".into(),
            signature: quote!(fn kinetic(&self, q: #q_ty, k: &mut KineticMatrices<#n>)),
            inputs: parts.q_inputs.clone(),
            groups: kinetic_groups(&quote!(k), &e.kinetic),
            ret: None,
            ret_wrap: None,
            barrier: None,
        });
    }
    specs.push(FunctionSpec {
        name: "kinetic_energy_gradient",
        doc: "∂T/∂q at fixed body-frame angular velocity and q̇; returns T.".into(),
        signature: quote!(
            fn kinetic_energy_gradient(
                &self,
                q: #q_ty,
                omega: &Vector3<f64>,
                qdot: #q_ty,
                grad: &mut SVector<f64, #n>,
            ) -> f64
        ),
        inputs: parts.velocity_inputs.clone(),
        groups: vec![gradient_group(quote!(grad), &e.kinetic_gradient)],
        ret: Some(e.kinetic_energy),
        ret_wrap: None,
        barrier: None,
    });
    if e.centre_of_mass_at_run_time.is_none() {
        let mut groups = kinetic_groups(&quote!(k), &e.kinetic);
        groups.push(gradient_group(quote!(grad), &e.kinetic_gradient));
        specs.push(FunctionSpec {
            name: "kinetic_and_gradient",
            doc: "The kinetic matrices into `k`, then (ω, q̇) from `velocities(k)`, then ∂T/∂q at those\n\
                  velocities into `grad`; both halves share every position term. Returns (ω, q̇, T)."
                .into(),
            signature: quote!(
                fn kinetic_and_gradient<E>(
                    &self,
                    q: #q_ty,
                    k: &mut KineticMatrices<#n>,
                    velocities: impl FnOnce(&KineticMatrices<#n>) -> Result<(Vector3<f64>, SVector<f64, #n>), E>,
                    grad: &mut SVector<f64, #n>,
                ) -> Result<(Vector3<f64>, SVector<f64, #n>, f64), E>
            ),
            inputs: parts.velocity_inputs.clone(),
            groups,
            ret: Some(e.kinetic_energy),
            ret_wrap: Some(|t| quote!(Ok((omega, qdot, #t)))),
            barrier: Some(Barrier {
                groups_before: 3,
                statement: quote!(let (omega, qdot) = velocities(k)?;),
                late_vars: (nc..2 * nc + 3).map(|v| v as u32).collect(),
            }),
        });
    }
    if let Some(c) = cartesian {
        specs.extend(
            crate::cartesian::specs(c, nc, &def.graph).into_iter().filter(|s| s.name == "internal_coordinates"),
        );
    }
    // The symbolic ∂a/∂q, ∂A/∂q, ∂I/∂q only on request (kinetic::Options): by default the
    // runtime's `Kinematics::kinetic_jacobian` assembles them from `kinetic_energy_gradient`.
    if let Some(kinetic_jacobian) = &e.kinetic_jacobian {
        specs.push(FunctionSpec {
            name: "kinetic_jacobian",
            doc: "`dk[l]` holds ∂a/∂q_l, ∂A/∂q_l and ∂I/∂q_l.".into(),
            signature: quote!(fn kinetic_jacobian(&self, q: #q_ty, dk: &mut [KineticMatrices<#n>; #n])),
            inputs: parts.q_inputs.clone(),
            groups: kinetic_jacobian
                .iter()
                .enumerate()
                .flat_map(|(l, set)| kinetic_groups(&ix(quote!(dk), l), set))
                .collect(),
            ret: None,
            ret_wrap: None,
            barrier: None,
        });
    }
    specs
}

/// The `Atom` entries of `atoms()`: label, element, mass in Da and in electron masses.
fn atom_table(def: &Definition) -> Vec<TokenStream> {
    def.atoms
        .iter()
        .map(|a| {
            let (label, element) = (&a.label, &a.element);
            let (mass_da, mass) = (float(a.mass_da), float(a.mass_da * DALTON_IN_ELECTRON_MASSES));
            quote!(Atom { label: #label, element: #element, mass_da: #mass_da, mass: #mass })
        })
        .collect()
}

/// The `Coordinate` entries of `coordinates()`: name, unit, reference and range in atomic units.
fn coordinate_table(def: &Definition) -> Vec<TokenStream> {
    def.coordinates
        .iter()
        .map(|c| {
            let name = &c.name;
            let unit = unit_tokens(c.unit);
            let reference = match c.reference {
                Some(r) => {
                    let r = float(r * c.unit.in_atomic_units());
                    quote!(Some(#r))
                }
                None => quote!(None),
            };
            let (low, high) =
                (bound(c.range.0 * c.unit.in_atomic_units()), bound(c.range.1 * c.unit.in_atomic_units()));
            quote!(Coordinate { name: #name, unit: #unit, reference: #reference, range: (#low, #high) })
        })
        .collect()
}

/// For a large molecule (`a` gets its centre-of-mass term at run time): the inherent `*_sparse`
/// functions, which emit `a` without that term plus `∂c/∂q`, and the `kinetic` and
/// `kinetic_and_gradient` trait methods that wrap them with the runtime's rank-3 update
/// (`kinetic::RunTimeCentreOfMass`). Nothing otherwise.
fn centre_of_mass_items(parts: &Parts, stats: &mut Vec<FunctionStats>) -> (Vec<TokenStream>, TokenStream) {
    let (e, n, q_ty) = (parts.e, &parts.n, &parts.q_ty);
    let Some(c) = &e.centre_of_mass_at_run_time else {
        return (Vec::new(), quote!());
    };
    let nc = e.n;
    let sparse = KineticSet { a: c.a.clone(), coriolis: e.kinetic.coriolis.clone(), inertia: e.kinetic.inertia };
    let sparse_groups = || {
        let mut groups = kinetic_groups(&quote!(k), &sparse);
        groups.push(OutputGroup {
            target: quote!(dc),
            entries: (0..nc).flat_map(|k| (0..3).map(move |axis| (pair(axis, k), c.dcom[k][axis]))).collect(),
        });
        groups
    };
    let total = float(c.total);
    let dc_ty = quote!(&mut SMatrix<f64, 3, #n>);
    let mut groups = sparse_groups();
    groups.push(gradient_group(quote!(grad), &e.kinetic_gradient));
    let specs = [
        FunctionSpec {
            name: "kinetic",
            doc: "`a` without its centre-of-mass term, `A` and `I` into `k`, and ∂c/∂q into `dc` (the centre of\n\
                  mass's derivatives, column k along q_k)."
                .into(),
            signature: quote!(fn kinetic_sparse(&self, q: #q_ty, k: &mut KineticMatrices<#n>, dc: #dc_ty)),
            inputs: parts.q_inputs.clone(),
            groups: sparse_groups(),
            ret: None,
            ret_wrap: None,
            barrier: None,
        },
        FunctionSpec {
            name: "kinetic_and_gradient",
            doc: "[`Kinematics::kinetic_and_gradient`] with ∂c/∂q in `dc`: `a` is completed by the runtime's\n\
                  centre-of-mass update before `velocities(k)` is called; `None` if `velocities` returns `None`.\n\
                  Not generic (`velocities` is `dyn`), so that its large body is compiled once, not once per\n\
                  caller."
                .into(),
            signature: quote!(
                fn kinetic_and_gradient_sparse(
                    &self,
                    q: #q_ty,
                    k: &mut KineticMatrices<#n>,
                    dc: #dc_ty,
                    velocities: &mut ::rovib_runtime::assembly::Velocities<'_, #n>,
                    grad: &mut SVector<f64, #n>,
                ) -> Option<(Vector3<f64>, SVector<f64, #n>, f64)>
            ),
            inputs: parts.velocity_inputs.clone(),
            groups,
            ret: Some(e.kinetic_energy),
            ret_wrap: Some(|t| quote!(Some((omega, qdot, #t)))),
            barrier: Some(Barrier {
                groups_before: 4,
                statement: quote! {
                    ::rovib_runtime::assembly::remove_centre_of_mass(&mut k.a, dc, #total);
                    let (omega, qdot) = velocities(k)?;
                },
                late_vars: (nc..2 * nc + 3).map(|v| v as u32).collect(),
            }),
        },
    ];
    let inherent = parts.emit(&specs, stats);
    let wrappers = quote! {
        /// The kinetic matrices a, A (coriolis) and I at q; the centre-of-mass term of `a` is applied
        /// by the runtime.
        fn kinetic(&self, q: #q_ty, k: &mut KineticMatrices<#n>) {
            let mut dc = SMatrix::<f64, 3, #n>::zeros();
            self.kinetic_sparse(q, k, &mut dc);
            ::rovib_runtime::assembly::remove_centre_of_mass(&mut k.a, &dc, #total);
        }

        /// The kinetic matrices into `k`, then (ω, q̇) from `velocities(k)`, then ∂T/∂q at those
        /// velocities into `grad`. Returns (ω, q̇, T). `velocities` goes to the one
        /// non-generic `kinetic_and_gradient_sparse` as `dyn`, its error through `failure`.
        fn kinetic_and_gradient<E>(
            &self,
            q: #q_ty,
            k: &mut KineticMatrices<#n>,
            velocities: impl FnOnce(&KineticMatrices<#n>) -> Result<(Vector3<f64>, SVector<f64, #n>), E>,
            grad: &mut SVector<f64, #n>,
        ) -> Result<(Vector3<f64>, SVector<f64, #n>, f64), E> {
            let mut dc = SMatrix::<f64, 3, #n>::zeros();
            let mut velocities = Some(velocities);
            let mut failure = None;
            let done = self.kinetic_and_gradient_sparse(
                q,
                k,
                &mut dc,
                &mut |k| match velocities.take()?(k) {
                    Ok(v) => Some(v),
                    Err(e) => {
                        failure = Some(e);
                        None
                    }
                },
                grad,
            );
            match (done, failure) {
                (Some(out), _) => Ok(out),
                (None, Some(e)) => Err(e),
                (None, None) => unreachable!("kinetic_and_gradient_sparse fails only where velocities does"),
            }
        }
    };
    (inherent, wrappers)
}

/// The body of `impl Molecule`: the potential (generated, or calling the definition's source
/// files), its parameters, its Cartesian forms and lane form, and the dipole surface's accessor.
fn molecule_impl(
    parts: &Parts,
    cartesian: Option<&CartesianExprs>,
    parametric: Option<&ParametricExprs>,
    has_dipole: bool,
    stats: &mut Vec<FunctionStats>,
) -> TokenStream {
    let (def, e, n, q_ty) = (parts.def, parts.e, &parts.n, &parts.q_ty);
    let mut specs = Vec::new();
    if def.external.is_none() {
        specs.push(FunctionSpec {
            name: "potential",
            doc: "The potential energy U(q) in hartree.".into(),
            signature: quote!(fn potential(&self, q: #q_ty) -> f64),
            inputs: parts.q_inputs.clone(),
            groups: vec![],
            ret: Some(e.potential),
            ret_wrap: None,
            barrier: None,
        });
        specs.push(FunctionSpec {
            name: "potential_gradient",
            doc: "∂U/∂q in hartree per unit of q; returns U.".into(),
            signature: quote!(fn potential_gradient(&self, q: #q_ty, grad: &mut SVector<f64, #n>) -> f64),
            inputs: parts.q_inputs.clone(),
            groups: vec![gradient_group(quote!(grad), &e.potential_gradient)],
            ret: Some(e.potential),
            ret_wrap: None,
            barrier: None,
        });
    }
    if let Some(c) = cartesian {
        specs.extend(
            crate::cartesian::specs(c, e.n, &def.graph).into_iter().filter(|s| s.name != "internal_coordinates"),
        );
    }
    let mut parameters = quote!();
    if let Some(p) = parametric {
        let mut inputs = parts.q_inputs.clone();
        inputs.extend((0..def.parameters.len()).map(|i| (p.first_var + i as u32, ix(quote!(params), i))));
        specs.push(FunctionSpec {
            name: "potential_with",
            doc: "U(q) in hartree with the parameters `params` (in the order of `parameters()`) instead of the\n\
                  compiled-in values."
                .into(),
            signature: quote!(fn potential_with(&self, q: #q_ty, params: &[f64]) -> f64),
            inputs: inputs.clone(),
            groups: vec![],
            ret: Some(p.potential),
            ret_wrap: None,
            barrier: None,
        });
        specs.push(FunctionSpec {
            name: "potential_gradient_with",
            doc: "∂U/∂q with the parameters `params`; returns U.".into(),
            signature: quote!(
                fn potential_gradient_with(&self, q: #q_ty, params: &[f64], grad: &mut SVector<f64, #n>) -> f64
            ),
            inputs,
            groups: vec![gradient_group(quote!(grad), &p.gradient)],
            ret: Some(p.potential),
            ret_wrap: None,
            barrier: None,
        });
        let entries = def.parameters.iter().map(|(name, value)| {
            let value = float(*value);
            quote!((#name, #value))
        });
        parameters = quote! {
            fn parameters(&self) -> &'static [(&'static str, f64)] {
                &[#(#entries),*]
            }
        };
    }
    let functions = parts.emit(&specs, stats);
    let mut lanes = quote!();
    if parts.lanes() {
        let potential_lanes = if def.external.is_none() { parts.lane_functions().1 } else { quote!() };
        let cartesian_lanes = match cartesian {
            Some(c) => {
                emit::emit_function_as(&def.graph, &crate::cartesian::lane_spec(c), &parts.idents, emit::Flavor::Lanes)
                    .0
            }
            None => quote!(),
        };
        lanes = quote! {
            #potential_lanes

            #cartesian_lanes

            fn has_lane_forms(&self) -> bool {
                true
            }
        };
    }
    let external = match &def.external {
        Some(x) => crate::external::items(x, &def.name, e.n, parts.lanes()).1,
        None => quote!(),
    };
    let dipole = if has_dipole {
        quote! {
            /// The dipole surface of the definition's `[dipole]` table: this type's `Dipole` impl.
            fn dipole(&self) -> Option<impl Dipole<#n>> {
                Some(*self)
            }
        }
    } else {
        quote!()
    };
    quote! {
        #parameters

        #(#functions)*

        #lanes

        #external

        #dipole
    }
}

/// `impl Dipole` for a definition with a `[dipole]` table: μ(q) and ∂μ/∂q.
fn dipole_impl(parts: &Parts, d: &DipoleExprs, stats: &mut Vec<FunctionStats>) -> TokenStream {
    let (def, n, q_ty) = (parts.def, &parts.n, &parts.q_ty);
    let ty = Ident::new(&type_name(&def.name), Span::call_site());
    let mut entries = Vec::new();
    for (k, column) in d.jacobian.iter().enumerate() {
        for (axis, &c) in column.iter().enumerate() {
            entries.push((pair(axis, k), c));
        }
    }
    let specs = [
        FunctionSpec {
            name: "dipole",
            doc: "The body-frame dipole moment μ(q) in e·bohr.".into(),
            signature: quote!(fn moment(&self, q: #q_ty, mu: &mut Vector3<f64>)),
            inputs: parts.q_inputs.clone(),
            groups: vec![gradient_group(quote!(mu), &d.mu)],
            ret: None,
            ret_wrap: None,
            barrier: None,
        },
        FunctionSpec {
            name: "dipole_jacobian",
            doc: "`dmu[(axis, k)]` = ∂μ_axis/∂q_k, e·bohr per unit of q_k.".into(),
            signature: quote!(fn moment_jacobian(&self, q: #q_ty, dmu: &mut SMatrix<f64, 3, #n>)),
            inputs: parts.q_inputs.clone(),
            groups: vec![OutputGroup { target: quote!(dmu), entries }],
            ret: None,
            ret_wrap: None,
            barrier: None,
        },
    ];
    let functions = parts.emit(&specs, stats);
    quote! {
        impl Dipole<#n> for #ty {
            #(#functions)*
        }
    }
}

/// The generated `molecules.rs`: one module per molecule, their names, and a dispatcher from a
/// name to the monomorphised code (`visit`).
pub(crate) fn registry(molecules: &[GeneratedMolecule], display_dir: &str) -> String {
    let modules = molecules.iter().map(|m| {
        let module = Ident::new(&m.name, Span::call_site());
        let ty = Ident::new(&m.type_name, Span::call_site());
        let file = format!("/{}", file_name(&m.name));
        let doc = format!(" Generated from `{}`.", m.path);
        quote! {
            #[doc = #doc]
            pub mod #module {
                include!(concat!(env!("OUT_DIR"), #file));
            }
            pub use #module::#ty;
        }
    });
    let names: Vec<&str> = molecules.iter().map(|m| m.name.as_str()).collect();
    let count = names.len();
    let arms = molecules.iter().map(|m| {
        let name = &m.name;
        let ty = Ident::new(&m.type_name, Span::call_site());
        quote!(#name => Some(visitor.visit(#ty)),)
    });
    let items = quote! {
        #(#modules)*

        /// The names of all compiled-in molecules, sorted.
        pub const NAMES: [&str; #count] = [#(#names),*];

        /// Calls `visitor` with the molecule called `name`, or returns `None` if there is none.
        pub fn visit<V: ::rovib_runtime::MoleculeVisitor>(name: &str, visitor: V) -> Option<V::Output> {
            match name {
                #(#arms)*
                _ => None,
            }
        }
    };
    let header = format!("// @generated from {display_dir} (*.toml) by rovib-codegen; do not edit.");
    emit::format_file(&header, items).expect("the registry is valid Rust")
}
