//! The molecule definition file (TOML) and its validation into expressions.
//!
//! A definition names the atoms, the internal coordinates, each atom's body-frame position as
//! expressions of the coordinates, and the potential. The full format, with an example, is in
//! the guide (docs/src/reference/definition.md); in short:
//!
//! ```toml
//! name = "h2o"                     # must match the file name: molecules/h2o.toml
//! description = "Water in valence coordinates"
//! length_unit = "angstrom"         # unit of the position expressions: "bohr" (default) or "angstrom"
//!
//! [constants]                      # optional named numbers usable in positions and potential
//! half = 0.5
//!
//! [[coordinates]]                  # in order: this is the order of q and p
//! name = "r1"
//! unit = "angstrom"                # bohr | angstrom | rad | deg
//! reference = 0.9578               # optional, in `unit`
//! range = [0, "inf"]               # optional valid values in `unit` (default: lengths [0, inf],
//!                                  # angles [-inf, inf]; bond angles declare [0, 180] deg)
//!
//! [[atoms]]
//! label = "H1"                     # unique; the element is read from its leading letters
//! position = ["r1 * sin(alpha * half)", 0, "r1 * cos(alpha * half)"]
//! # element = "H", isotope = 2, mass = 2.014   (optional; mass in Da overrides the table)
//!
//! [potential]
//! energy_unit = "cm-1"             # hartree | cm-1 | eV | kcal/mol
//! expression = "D * pow(1 - exp(-a * (r1 - re)), 2)"
//! parameters = { D = 44000, a = 2.2, re = 0.9578 }
//!
//! [dipole]                         # optional: the body-frame dipole moment μ(q), either
//! unit = "debye"                   # debye | e*bohr | e*angstrom
//! components = ["0", "0", "mu0 + d1 * (r1 - re)"]
//! parameters = { mu0 = 1.85, d1 = 0.5 }
//! # or, the short form, charges in e per atom label (numbers or expressions of q), with
//! # μ = Σ q_i R_i about the centre of mass:
//! # charges = { O = "-2 * qh", H1 = "qh", H2 = "qh" }
//! ```
//!
//! In every expression a coordinate's name stands for its value in the coordinate's declared
//! unit; trigonometric functions take radians, so a coordinate declared in degrees is used as
//! `cos(theta * pi / 180)`. The generator converts everything to atomic units: the generated
//! code takes q in bohr and radians, and returns positions in bohr and energies in hartree.
//!
//! Every problem is reported as a [`DefinitionError`] naming the file, line and column, what is
//! wrong and what to change; [`parse_definition`] reports every independent problem of a file at
//! once, in file order.

use std::collections::{BTreeMap, HashMap};
use std::ops::Range;

use serde::Deserialize;
use toml::Spanned;

use crate::diagnostic::Source;
use crate::elements;
use crate::expr::{ExprId, Func, Graph, Node};
use crate::parse::{self, BINARY_FUNCTIONS, Library, Scope};
use crate::units::{CoordinateUnit, DALTON_IN_ELECTRON_MASSES, DipoleUnit, EnergyUnit, LengthUnit};

pub use crate::definition_error::DefinitionError;
pub(crate) use crate::definition_error::ExpressionPlace;

/// An atom after validation.
#[derive(Clone, Debug, PartialEq)]
pub struct AtomDef {
    /// Unique label.
    pub label: String,
    /// Element symbol.
    pub element: String,
    /// Mass in daltons.
    pub mass_da: f64,
}

/// An internal coordinate after validation.
#[derive(Clone, Debug, PartialEq)]
pub struct CoordinateDef {
    /// Name (a valid identifier).
    pub name: String,
    /// Declared unit.
    pub unit: CoordinateUnit,
    /// Reference value in the declared unit.
    pub reference: Option<f64>,
    /// The valid values, a closed interval in the declared unit: as declared, else
    /// [`default_range`].
    pub range: (f64, f64),
}

/// A validated molecule: metadata plus its positions and potential as expressions in one graph.
///
/// Graph variable `k` (for `k < coordinates.len()`) is coordinate `k` in atomic units; the
/// positions are in bohr, not yet centred; the potential is in hartree.
#[derive(Clone, Debug)]
pub struct Definition {
    /// The file it came from, as given to the generator.
    pub path: String,
    /// Molecule name (file stem), a lowercase identifier.
    pub name: String,
    /// One-line description.
    pub description: String,
    /// Atoms in file order.
    pub atoms: Vec<AtomDef>,
    /// Coordinates in file order.
    pub coordinates: Vec<CoordinateDef>,
    /// The expression graph.
    pub graph: Graph,
    /// Uncentred body-frame positions, in bohr, one `[x, y, z]` per atom.
    pub positions: Vec<[ExprId; 3]>,
    /// The potential in hartree.
    pub potential: ExprId,
    /// The energy unit the file used for the potential.
    pub energy_unit: EnergyUnit,
    /// The coordinates' kinds, in coordinate order, when the definition declares coordinates by
    /// kind (then `positions` are the Z-matrix construction of [`crate::zmatrix`]); `None` for
    /// explicit positions.
    pub kinds: Option<Vec<crate::zmatrix::Kind>>,
    /// The potential's parameters, sorted by name, with their values as written (in the units
    /// the potential expression uses them in).
    pub parameters: Vec<(String, f64)>,
    /// The names the potential expression sees (parameters bound to their values) and its text,
    /// to build it again with the parameters as variables (`crate::parametric`).
    pub potential_scope: HashMap<String, ExprId>,
    /// See `potential_scope`.
    pub potential_text: String,
    /// The functions and named expressions, inlined where used (also when the potential is
    /// built again).
    pub library: Library,
    /// The data files the definition read (CSV files of `[arrays]`).
    pub data_files: Vec<std::path::PathBuf>,
    /// Where the potential comes from when the definition names source files instead of an
    /// expression (`potential` is then the constant 0 and not emitted).
    pub external: Option<crate::external::ExternalPotential>,
    /// The dipole moment surface, if the file has a `[dipole]` table.
    pub dipole: Option<DipoleDef>,
}

/// A validated `[dipole]` table, in atomic units.
#[derive(Clone, Debug)]
pub enum DipoleDef {
    /// The body-frame components `[μx, μy, μz]` in e·bohr.
    Components([ExprId; 3]),
    /// One charge per atom (in atom order) in e: μ = Σ q_i R_i with the centred positions.
    Charges(Vec<ExprId>),
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawDefinition {
    name: Spanned<String>,
    #[serde(default)]
    description: Option<String>,
    #[serde(default)]
    length_unit: Option<Spanned<String>>,
    #[serde(default)]
    constants: BTreeMap<Spanned<String>, Spanned<RawValue>>,
    #[serde(default)]
    functions: BTreeMap<Spanned<String>, Spanned<String>>,
    #[serde(default)]
    expressions: BTreeMap<Spanned<String>, Spanned<String>>,
    #[serde(default)]
    arrays: BTreeMap<Spanned<String>, Spanned<crate::arrays::RawArray>>,
    #[serde(default)]
    coordinates: Vec<RawCoordinate>,
    atoms: Vec<RawAtom>,
    potential: Spanned<RawPotential>,
    #[serde(default)]
    dipole: Option<Spanned<RawDipole>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawDipole {
    #[serde(default)]
    unit: Option<Spanned<String>>,
    #[serde(default)]
    components: Option<Spanned<Vec<Spanned<RawValue>>>>,
    #[serde(default)]
    charges: Option<BTreeMap<Spanned<String>, Spanned<RawValue>>>,
    #[serde(default)]
    parameters: BTreeMap<Spanned<String>, Spanned<f64>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawCoordinate {
    name: Spanned<String>,
    unit: Spanned<String>,
    #[serde(default)]
    reference: Option<Spanned<f64>>,
    #[serde(default)]
    range: Option<Spanned<Vec<Spanned<RawValue>>>>,
    /// What the coordinate is, e.g. `"angle(H1, O, H2)"` ([`crate::zmatrix`]).
    #[serde(default)]
    kind: Option<Spanned<String>>,
    #[serde(default)]
    #[allow(dead_code)]
    description: Option<String>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawAtom {
    label: Spanned<String>,
    #[serde(default)]
    element: Option<Spanned<String>>,
    #[serde(default)]
    isotope: Option<Spanned<u32>>,
    #[serde(default)]
    mass: Option<Spanned<f64>>,
    #[serde(default)]
    position: Option<Spanned<Vec<Spanned<RawValue>>>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawPotential {
    #[serde(default)]
    expression: Option<Spanned<String>>,
    energy_unit: Spanned<String>,
    #[serde(default)]
    parameters: BTreeMap<Spanned<String>, Spanned<f64>>,
    /// A Rust source file instead of `expression` ([`crate::external`]).
    #[serde(default)]
    rust: Option<Spanned<String>>,
    /// C, C++ and Fortran sources instead of `expression`.
    #[serde(default)]
    c: Option<Spanned<Vec<String>>>,
    #[serde(default)]
    cpp: Option<Spanned<Vec<String>>>,
    #[serde(default)]
    fortran: Option<Spanned<Vec<String>>>,
}

/// A number or an expression, as a position component or constant.
#[derive(Deserialize, Clone)]
#[serde(untagged)]
enum RawValue {
    Int(i64),
    Float(f64),
    Expr(String),
}

/// The valid values of a coordinate that declares no range: lengths are positive,
/// angles unbounded (dihedrals and torsions wrap; bond angles declare [0, 180] deg).
pub fn default_range(unit: CoordinateUnit) -> (f64, f64) {
    match unit {
        CoordinateUnit::Length(_) => (0.0, f64::INFINITY),
        CoordinateUnit::Angle(_) => (f64::NEG_INFINITY, f64::INFINITY),
    }
}

/// The value that stands in for a constant or parameter with a problem, so that the rest of the
/// definition can still be checked (never emitted: a definition with a problem generates nothing).
const PLACEHOLDER: f64 = 1.0;

/// The punctuation an atom label may contain besides letters and digits.
const LABEL_PUNCTUATION: &str = "_-+'.*()";

/// The longest atom label, in characters.
const MAX_LABEL_CHARS: usize = 32;

/// Whether `c` may appear in an atom label: a letter, a digit or [`LABEL_PUNCTUATION`] (no
/// whitespace, control characters, commas or quotes, which break lists and files).
fn label_char(c: char) -> bool {
    c.is_alphanumeric() || LABEL_PUNCTUATION.contains(c)
}

fn is_identifier(name: &str) -> bool {
    let mut chars = name.chars();
    matches!(chars.next(), Some(c) if c.is_ascii_alphabetic() || c == '_')
        && chars.all(|c| c.is_ascii_alphanumeric() || c == '_')
        && syn::parse_str::<syn::Ident>(name).is_ok()
}

fn unit_help<T>(spellings: &[(&str, T)]) -> String {
    let names: Vec<String> = spellings.iter().map(|(n, _)| format!("\"{n}\"")).collect();
    format!("use one of {}", names.join(", "))
}

/// Reads and validates one definition. `path` is used in messages only.
///
/// Every problem is reported, not only the first: the errors come in file order. A TOML syntax
/// error or an unknown or missing key stops the reading at that place (the rest of the file
/// cannot be read reliably); after that, every independent mistake gets its own error.
pub fn parse_definition(path: &str, text: &str) -> Result<Definition, Vec<DefinitionError>> {
    parse_definition_in(path, text, std::path::Path::new(path).parent())
}

/// [`parse_definition`] with the directory that paths in the definition (CSV files of
/// `[arrays]`) are relative to; `None` if there is none.
pub fn parse_definition_in(
    path: &str,
    text: &str,
    base: Option<&std::path::Path>,
) -> Result<Definition, Vec<DefinitionError>> {
    let src = Source { path, text };
    let raw = toml::from_str::<RawDefinition>(text).map_err(|e| {
        let message = e.message().trim_end().trim_end_matches('.').to_owned();
        let help = if message.starts_with("unknown field") {
            "check the spelling; docs/src/reference/definition.md lists every key of a molecule definition".to_owned()
        } else if message.starts_with("missing field") {
            "add it; docs/src/reference/definition.md lists every key of a molecule definition".to_owned()
        } else if message.contains("did not match any variant of untagged enum RawArray") {
            "an array is a list of numbers, c = [1.0, 0.5], or a CSV file, c = { file = \"c.csv\", column = 2 }"
                .to_owned()
        } else if message.contains("did not match any variant of untagged enum RawValue") {
            "a position component or constant is a number or a string holding an expression".to_owned()
        } else {
            "see the TOML syntax at https://toml.io and the shipped molecules/h2o.toml".to_owned()
        };
        let message = message.replace("data did not match any variant of untagged enum RawValue", "invalid value");
        let message = message.replace("data did not match any variant of untagged enum RawArray", "invalid array");
        match e.span() {
            Some(span) => src.error(span, message, help),
            None => src.whole_file(message, help),
        }
    });
    let raw = raw.map_err(|e| vec![e])?;
    Validator {
        src: &src,
        graph: Graph::new(),
        names: HashMap::new(),
        declared: HashMap::new(),
        errors: Vec::new(),
        library: Library::default(),
        base,
        data_files: Vec::new(),
    }
    .run(raw)
}

/// State of one validation: the graph being built and the names declared so far.
struct Validator<'s> {
    src: &'s Source<'s>,
    graph: Graph,
    /// Name → expression, for coordinates, constants and parameters.
    names: HashMap<String, ExprId>,
    /// Name → (what it is, where it was declared), to report duplicates.
    declared: HashMap<String, (&'static str, Range<usize>)>,
    /// Every problem found so far.
    errors: Vec<DefinitionError>,
    /// The functions and named expressions (empty until the constants are known).
    library: Library,
    /// The definition's directory, for data files.
    base: Option<&'s std::path::Path>,
    /// The data files read.
    data_files: Vec<std::path::PathBuf>,
}

/// The atoms as read by [`Validator::atoms`].
struct ReadAtoms {
    atoms: Vec<AtomDef>,
    /// One per atom, `None` where the position has a problem.
    positions: Vec<Option<[ExprId; 3]>>,
    /// The place of each position component, for messages.
    position_spans: Vec<Vec<Range<usize>>>,
    /// Whether every mass was read.
    masses_ok: bool,
    /// Whether the coordinates declare their kinds.
    by_kind: bool,
    /// Whether the kinds place the atoms (no atom has a position).
    zmatrix_positions: bool,
}

/// The `[potential]` table as read by [`Validator::potential`].
struct ReadPotential {
    energy_unit: EnergyUnit,
    /// Whether every parameter was read.
    parameters_ok: bool,
    /// The names the potential expression sees.
    scope: HashMap<String, ExprId>,
    /// The potential in hartree (the constant 0 for source files), `None` where it has a problem.
    potential: Option<ExprId>,
    external: Option<crate::external::ExternalPotential>,
}

/// Where an expression's value is known before the molecule runs: everywhere for a constant, and
/// at the reference geometry (atomic units) if the file gives one.
struct Known {
    reference: Option<Vec<f64>>,
}

impl Known {
    /// The value of `e` where it is known now, and where that is (for the message).
    fn value(&self, graph: &Graph, e: ExprId) -> Option<(f64, &'static str)> {
        let varying = graph.reachable(&[e]).iter().zip(graph.nodes()).any(|(r, n)| *r && matches!(n, Node::Var(_)));
        match (&self.reference, varying) {
            (_, false) => Some((graph.eval(&[e], &[])[0], "(a constant)")),
            (Some(q), true) => Some((graph.eval(&[e], q)[0], "at the reference geometry")),
            (None, true) => None,
        }
    }
}

/// The molecule's name becomes a module and a type, and `--molecule NAME` finds it by file
/// name: the first thing wrong with it.
fn check_molecule_name(src: &Source, name: &Spanned<String>, stem: &str) -> Result<(), DefinitionError> {
    let span = name.span();
    let name = name.get_ref();
    let valid_name = name.chars().next().is_some_and(|c| c.is_ascii_lowercase())
        && name.chars().all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '_');
    if !valid_name {
        return Err(src.error(
            span,
            format!("molecule name `{name}` is not a lowercase identifier"),
            "use lowercase letters, digits and `_`, starting with a letter, e.g. \"h2o\"",
        ));
    }
    if crate::names::is_keyword(name) {
        return Err(src.error(
            span,
            format!("molecule name `{name}` is a Rust keyword"),
            "the name becomes a Rust module; choose another, e.g. \"h2o\" or \"water\"",
        ));
    }
    let ty = crate::names::type_name(name);
    if crate::names::RESERVED_TYPE_NAMES.contains(&ty.as_str()) {
        return Err(src.error(
            span,
            format!("molecule name `{name}` gives the type name `{ty}`, which generated code already uses"),
            "choose another name (the type name is the name in CamelCase)",
        ));
    }
    if name != stem {
        return Err(src.error(
            span,
            format!("molecule name `{name}` does not match the file name `{stem}.toml`"),
            format!("rename the file to `{name}.toml` or set name = \"{stem}\""),
        ));
    }
    Ok(())
}

/// The first thing wrong with an atom's label, given the labels of the atoms before it.
fn check_label(
    src: &Source,
    label: &Spanned<String>,
    earlier: &HashMap<String, Range<usize>>,
) -> Result<(), DefinitionError> {
    let span = label.span();
    let label = label.get_ref();
    if label.trim().is_empty() {
        return Err(src.error(span, "empty atom label", "give every atom a label such as \"H1\""));
    }
    // Labels are printed in lists (`rovib list`, messages) and are keys of scenes and states
    // files: one short word.
    if let Some(c) = label.chars().find(|&c| !label_char(c)) {
        return Err(src.error(
            span,
            format!("atom label {label:?} contains {c:?}"),
            format!("labels are one word of letters, digits and {LABEL_PUNCTUATION}, e.g. \"H1\""),
        ));
    }
    if label.chars().count() > MAX_LABEL_CHARS {
        return Err(src.error(
            span,
            format!("atom label `{label}` has {} characters, more than {MAX_LABEL_CHARS}", label.chars().count()),
            "use a short label such as \"H1\"",
        ));
    }
    if let Some(first) = earlier.get(label) {
        let (line, _) = src.place(first.start);
        return Err(src.error(
            span,
            format!("duplicate atom `{label}`: another atom on line {line} has the same label"),
            "give each atom its own label, e.g. \"H1\" and \"H2\"",
        ));
    }
    Ok(())
}

/// The names of the ensemble quantities that are not coordinates (rovib's
/// `ensemble::quantity`): statistics name coordinates and these in one namespace, so a coordinate
/// may not take one of them, nor start with `p_` (the momentum of coordinate NAME is `p_NAME`).
pub const RESERVED_QUANTITY_NAMES: [&str; 13] =
    ["T", "U", "H", "J", "Jx", "Jy", "Jz", "Lx", "Ly", "Lz", "mu_x", "mu_y", "mu_z"];

impl Validator<'_> {
    fn not_a_quantity(&self, name: &Spanned<String>) -> Result<(), DefinitionError> {
        let n = name.get_ref();
        if RESERVED_QUANTITY_NAMES.contains(&n.as_str()) || n.starts_with("p_") {
            return Err(self.src.error(
                name.span(),
                format!("the coordinate name `{n}` is the name of an ensemble quantity"),
                format!(
                    "ensemble statistics name coordinates and the quantities {} and p_NAME (a coordinate's \
                     momentum) alike; choose another name",
                    RESERVED_QUANTITY_NAMES.join(", ")
                ),
            ));
        }
        Ok(())
    }

    fn declare(&mut self, name: &Spanned<String>, what: &'static str) -> Result<(), DefinitionError> {
        let n = name.get_ref();
        if !is_identifier(n) {
            return Err(self.src.error(
                name.span(),
                format!("`{n}` is not a valid {what} name"),
                "names start with a letter and contain only letters, digits and `_` (and are not Rust keywords)",
            ));
        }
        if n == "pi"
            || Func::from_name(n).is_some()
            || BINARY_FUNCTIONS.contains(&n.as_str())
            || parse::SPECIAL_FUNCTIONS.iter().any(|(f, _)| f == n)
        {
            return Err(self.src.error(
                name.span(),
                format!("the {what} name `{n}` is reserved"),
                "`pi` and the function names (sin, cos, pow, ...) cannot be redefined; choose another name",
            ));
        }
        if let Some((other, span)) = self.declared.get(n) {
            let (line, _) = self.src.place(span.start);
            return Err(self.src.error(
                name.span(),
                format!("duplicate name `{n}`: already declared as a {other} on line {line}"),
                format!(
                    "rename this {what} or the {other}; every coordinate, constant and parameter needs its own name"
                ),
            ));
        }
        self.declared.insert(n.clone(), (what, name.span()));
        Ok(())
    }

    fn expression(&mut self, value: &Spanned<String>, context: &str) -> Result<ExprId, DefinitionError> {
        let scope = Scope { names: &self.names, context, library: &self.library, named: true };
        parse::parse_expression(&mut self.graph, value.get_ref(), &scope)
            .map_err(|e| self.src.expression_error(value.span(), value.get_ref(), e))
    }

    fn value(&mut self, value: &Spanned<RawValue>, context: &str) -> Result<ExprId, DefinitionError> {
        match value.get_ref() {
            RawValue::Int(i) => Ok(self.graph.constant(*i as f64)),
            RawValue::Float(x) if x.is_finite() => Ok(self.graph.constant(*x)),
            RawValue::Float(_) => {
                Err(self.src.error(value.span(), format!("non-finite number in {context}"), "write a finite number"))
            }
            RawValue::Expr(s) => self.expression(&Spanned::new(value.span(), s.clone()), context),
        }
    }

    /// Records a problem and carries on, so that every independent mistake in the file is
    /// reported at once; the value is `None` where the problem was.
    /// Adds `e` to the errors found so far and returns them all: for an error after which
    /// validation cannot go on (the coordinates by kind).
    /// Every problem so far and `e`, in file order: what a definition that cannot be read on
    /// returns.
    fn fail(&mut self, e: DefinitionError) -> Vec<DefinitionError> {
        self.errors.push(e);
        let mut errors = std::mem::take(&mut self.errors);
        errors.sort_by_key(|e| (e.line, e.column));
        errors
    }

    fn check<T>(&mut self, result: Result<T, DefinitionError>) -> Option<T> {
        result.map_err(|e| self.errors.push(e)).ok()
    }

    /// The `[potential]` table's route: `None` for an expression, else the source files it
    /// names (each must exist beside the definition; they become inputs of the build). Exactly
    /// one of `expression`, `rust` and the compiled lists (`c`, `cpp`, `fortran`) is given.
    fn external_potential(
        &mut self,
        table: &Spanned<RawPotential>,
    ) -> Result<Option<crate::external::ExternalPotential>, DefinitionError> {
        use crate::external::ExternalPotential;
        let src = self.src;
        let pot = table.get_ref();
        let compiled: Vec<(&str, &Spanned<Vec<String>>)> =
            [("c", &pot.c), ("cpp", &pot.cpp), ("fortran", &pot.fortran)]
                .into_iter()
                .filter_map(|(k, v)| v.as_ref().map(|v| (k, v)))
                .collect();
        let first_source =
            pot.rust.as_ref().map(|r| ("rust", r.span())).or(compiled.first().map(|(k, v)| (*k, v.span())));
        match (&pot.expression, first_source) {
            (None, None) => {
                return Err(src.error(
                    table.span(),
                    "`[potential]` has no `expression`",
                    "write the potential as `expression = \"...\"`, or name its code: `rust = \"surface.rs\"`, or \
                     `c = [\"surface.c\"]` (also `cpp`, `fortran`)",
                ));
            }
            (Some(_), None) => return Ok(None),
            (Some(_), Some((key, span))) => {
                return Err(src.error(
                    span,
                    format!("`potential.{key}` and `potential.expression` both give the potential"),
                    "keep one: the expression, or the source files",
                ));
            }
            (None, Some(_)) => {}
        }
        if let (Some(_), Some((key, v))) = (&pot.rust, compiled.first()) {
            return Err(src.error(
                v.span(),
                format!("`potential.{key}` and `potential.rust` both give the potential"),
                "name the Rust file or the compiled sources, not both",
            ));
        }
        if let Some((name, _)) = pot.parameters.iter().next() {
            return Err(src.error(
                name.span(),
                "`[potential.parameters]` are for a potential expression, not for source files",
                "remove [potential.parameters]; the source files hold their own constants",
            ));
        }
        if pot.energy_unit.get_ref() != "hartree" {
            return Err(src.error(
                pot.energy_unit.span(),
                format!("a potential from source files is in hartree, not `{}`", pot.energy_unit.get_ref()),
                "write `energy_unit = \"hartree\"` and return hartree from the code",
            ));
        }
        let base = self.base.unwrap_or(std::path::Path::new(""));
        let mut named: Vec<(String, Range<usize>)> = Vec::new();
        if let Some(rust) = &pot.rust {
            named.push((rust.get_ref().clone(), rust.span()));
        }
        for (key, list) in &compiled {
            if list.get_ref().is_empty() {
                return Err(src.error(
                    list.span(),
                    format!("`potential.{key}` lists no files"),
                    "name at least one source file",
                ));
            }
            named.extend(list.get_ref().iter().map(|f| (f.clone(), list.span())));
        }
        let mut paths = Vec::new();
        for (file, span) in named {
            let path = base.join(&file);
            if !path.is_file() {
                return Err(src.error(
                    span,
                    format!("`{file}` is not a file (looked for {})", path.display()),
                    "name a source file relative to the definition's directory",
                ));
            }
            paths.push(std::path::absolute(&path).unwrap_or(path));
        }
        self.data_files.extend(paths.iter().cloned());
        Ok(Some(match &pot.rust {
            Some(_) => ExternalPotential::Rust(paths.remove(0)),
            None => ExternalPotential::Compiled,
        }))
    }

    /// Validates everything, collecting every problem. A part with a problem is replaced by a
    /// stand-in (a default unit, a placeholder constant) so that later parts are still checked
    /// without reporting consequences of the first mistake as mistakes of their own; checks that
    /// evaluate expressions run only on parts that had no problem.
    fn run(mut self, raw: RawDefinition) -> Result<Definition, Vec<DefinitionError>> {
        let src = self.src;
        let name = raw.name.get_ref().clone();
        let stem = std::path::Path::new(src.path).file_stem().and_then(|s| s.to_str()).unwrap_or_default();
        let named = check_molecule_name(src, &raw.name, stem);
        self.check(named);
        let length_unit = self.length_unit(raw.length_unit.as_ref());
        let (mut coordinates, coordinate_spans) = self.coordinates(&raw.coordinates);
        let constants_ok = self.constants_and_library(&raw);
        let mut read = self.atoms(&raw, length_unit)?;
        let kinds = if read.by_kind { Some(self.kinds(&raw, &mut coordinates, &mut read)?) } else { None };
        self.check_total_mass(&read);
        // Every coordinate must move some atom, or the kinetic metric is singular (checked when
        // every position was read, so a broken position does not make its coordinates unused).
        let all_positions: Option<Vec<[ExprId; 3]>> = read.positions.iter().copied().collect();
        if let Some(all) = all_positions.as_deref().filter(|_| read.atoms.len() >= 2) {
            self.check_coordinates_used(all, &coordinates, &coordinate_spans);
        }
        let pot = raw.potential.get_ref();
        let potential = self.potential(&raw.potential);

        // Nothing non-finite where it can be known now: constant positions and a constant
        // potential everywhere, and everything at the reference geometry if the file gives one
        // (only for parts that had no problem, whose values mean what the file says).
        let known = Known {
            reference: coordinates.iter().map(|c| c.reference.map(|r| r * c.unit.in_atomic_units())).collect(),
        };
        if constants_ok {
            self.check_positions_finite(&read, &known);
        }
        if let Some(u) = potential.potential.filter(|_| constants_ok && potential.parameters_ok)
            && let Some(expression) = &pot.expression
            && let Some((v, place)) = known.value(&self.graph, u).filter(|(v, _)| !v.is_finite())
        {
            self.errors.push(src.error(
                expression.span(),
                format!("the potential is {v} hartree {place}"),
                "check for a division by zero, the logarithm or square root of a negative number, or values too large in hartree",
            ));
        }
        let dipole = raw.dipole.as_ref().and_then(|d| self.dipole_table(d, &read.atoms, &known, constants_ok));

        let (Some(positions), Some(potential_id), true) = (all_positions, potential.potential, self.errors.is_empty())
        else {
            let mut errors = self.errors;
            // In file order; problems of the whole file first.
            errors.sort_by_key(|e| (e.line, e.column));
            return Err(errors);
        };
        Ok(Definition {
            path: src.path.to_owned(),
            name,
            description: raw.description.unwrap_or_default().trim().to_owned(),
            atoms: read.atoms,
            coordinates,
            graph: self.graph,
            positions,
            potential: potential_id,
            energy_unit: potential.energy_unit,
            kinds,
            parameters: pot.parameters.iter().map(|(k, v)| (k.get_ref().clone(), *v.get_ref())).collect(),
            potential_scope: potential.scope,
            potential_text: pot.expression.as_ref().map(|e| e.get_ref().clone()).unwrap_or_default(),
            library: self.library,
            data_files: self.data_files,
            external: potential.external,
            dipole,
        })
    }

    /// `length_unit`: bohr when absent (and in place of an unknown unit).
    fn length_unit(&mut self, unit: Option<&Spanned<String>>) -> LengthUnit {
        let src = self.src;
        match unit {
            None => LengthUnit::Bohr,
            Some(u) => {
                let unit = LengthUnit::parse(u.get_ref()).ok_or_else(|| {
                    src.error(
                        u.span(),
                        format!("unknown length unit `{}`", u.get_ref()),
                        unit_help(LengthUnit::SPELLINGS),
                    )
                });
                self.check(unit).unwrap_or(LengthUnit::Bohr)
            }
        }
    }

    /// The coordinates, in file order, and the place of each name: graph variable k is
    /// coordinate k, in atomic units. A coordinate with a problem still gets its variable and its
    /// name, so expressions using it parse.
    fn coordinates(&mut self, raw: &[RawCoordinate]) -> (Vec<CoordinateDef>, Vec<Range<usize>>) {
        let src = self.src;
        let mut coordinates = Vec::new();
        let mut coordinate_spans = Vec::new();
        for c in raw {
            let declared = self.declare(&c.name, "coordinate").and_then(|()| self.not_a_quantity(&c.name));
            self.check(declared);
            let unit = CoordinateUnit::parse(c.unit.get_ref()).ok_or_else(|| {
                let mut spellings: Vec<(&str, ())> = LengthUnit::SPELLINGS.iter().map(|(n, _)| (*n, ())).collect();
                spellings.extend(crate::units::AngleUnit::SPELLINGS.iter().map(|(n, _)| (*n, ())));
                src.error(
                    c.unit.span(),
                    format!("unknown unit `{}` for coordinate `{}`", c.unit.get_ref(), c.name.get_ref()),
                    unit_help(&spellings),
                )
            });
            let unit = self.check(unit).unwrap_or(CoordinateUnit::Length(LengthUnit::Bohr));
            let reference = match &c.reference {
                Some(r) if !r.get_ref().is_finite() => {
                    self.errors.push(src.error(r.span(), "non-finite reference value", "write a finite number"));
                    None
                }
                Some(r) if !(r.get_ref() * unit.in_atomic_units()).is_finite() => {
                    self.errors.push(src.error(
                        r.span(),
                        format!("reference value {:?} {} overflows in atomic units", r.get_ref(), c.unit.get_ref()),
                        "write the reference geometry's value of this coordinate, a number of ordinary size",
                    ));
                    None
                }
                r => r.as_ref().map(|r| *r.get_ref()),
            };
            let var = self.graph.var(c.name.get_ref());
            // The name in expressions is the value in the declared unit: q_au / (au per unit).
            let symbol = if unit.in_atomic_units() == 1.0 {
                var
            } else {
                let factor = self.graph.constant(1.0 / unit.in_atomic_units());
                self.graph.mul(factor, var)
            };
            self.names.insert(c.name.get_ref().clone(), symbol);
            let range = self.range(c, unit);
            let range = self.check(range);
            if let (Some(r), Some(value), Some(range)) = (&c.reference, reference, range)
                && !(range.0 <= value && value <= range.1)
            {
                self.errors.push(src.error(
                    r.span(),
                    format!(
                        "reference value {value:?} of `{}` is outside its range [{:?}, {:?}] {}",
                        c.name.get_ref(),
                        range.0,
                        range.1,
                        c.unit.get_ref()
                    ),
                    "correct the reference, or declare the range of valid values with range = [low, high]",
                ));
            }
            let range = range.unwrap_or(default_range(unit));
            coordinates.push(CoordinateDef { name: c.name.get_ref().clone(), unit, reference, range });
            coordinate_spans.push(c.name.span());
        }
        (coordinates, coordinate_spans)
    }

    /// The constants (which may refer to each other in any order but not to coordinates), the
    /// arrays, and the functions and named expressions, checked once here and inlined where they
    /// are used. Whether all of them are free of problems (then their values can be evaluated).
    fn constants_and_library(&mut self, raw: &RawDefinition) -> bool {
        let src = self.src;
        let before_constants = self.errors.len();
        let constants: Vec<(Spanned<String>, Spanned<RawValue>)> =
            raw.constants.iter().map(|(k, v)| (k.clone(), v.clone())).collect();
        for (k, _) in &constants {
            let declared = self.declare(k, "constant");
            self.check(declared);
        }
        let coordinate_names: HashMap<String, ExprId> = std::mem::take(&mut self.names);
        self.resolve_constants(&constants);
        let constant_values: HashMap<String, f64> = constants
            .iter()
            .filter_map(|(k, _)| {
                let id = self.names.get(k.get_ref())?;
                Some((k.get_ref().clone(), self.graph.as_const(*id)?))
            })
            .collect();
        self.names.extend(coordinate_names);

        // Functions and named expressions.
        let mut names: Vec<String> = self.names.keys().cloned().collect();
        names.extend(raw.potential.get_ref().parameters.keys().map(|k| k.get_ref().clone()));
        names.extend(raw.dipole.iter().flat_map(|d| d.get_ref().parameters.keys().map(|k| k.get_ref().clone())));
        let (arrays, data_files, array_errors) = crate::arrays::read(src, &raw.arrays, self.base);
        let arrays_ok = array_errors.is_empty();
        self.errors.extend(array_errors);
        self.data_files = data_files;
        for (k, _) in &arrays {
            let declared = self.declare(k, "array");
            self.check(declared);
        }
        let input = crate::library::Input {
            functions: &raw.functions,
            expressions: &raw.expressions,
            constants: constant_values,
            arrays: arrays.into_iter().map(|(k, v)| (k.into_inner(), v)).collect(),
            names,
        };
        let (library, library_errors) = {
            let mut declare = |k: &Spanned<String>, what: &'static str| self.declare(k, what);
            crate::library::validate(src, input, &mut declare)
        };
        let library_ok = library_errors.is_empty() && arrays_ok;
        self.errors.extend(library_errors);
        self.library = library;
        self.errors.len() == before_constants && library_ok
    }

    /// The atoms and their positions (`None` where a position has a problem). Coordinates by
    /// kind (every coordinate says what it is) place the atoms themselves: with kinds and no
    /// positions the generator places them; with kinds and positions the positions are used and
    /// checked against the kinds ([`Validator::kinds`]).
    fn atoms(&mut self, raw: &RawDefinition, length_unit: LengthUnit) -> Result<ReadAtoms, Vec<DefinitionError>> {
        let src = self.src;
        if raw.atoms.len() < 2 {
            self.errors.push(src.whole_file(
                format!("a molecule needs at least 2 atoms, this one has {}", raw.atoms.len()),
                "add [[atoms]] entries, each with a label and a position",
            ));
        }
        // Coordinates by kind (every coordinate says what it is) place the atoms themselves.
        let by_kind = raw.coordinates.iter().any(|c| c.kind.is_some());
        if by_kind && let Some(c) = raw.coordinates.iter().find(|c| c.kind.is_none()) {
            return Err(self.fail(src.error(
                c.name.span(),
                format!("coordinate `{}` has no kind, but other coordinates declare theirs", c.name.get_ref()),
                "declare every coordinate's kind (distance, angle, dihedral) or none (then every atom needs a position)",
            )));
        }
        let zmatrix_positions = by_kind && raw.atoms.iter().any(|a| a.position.is_none());
        let mut atoms = Vec::new();
        let mut positions: Vec<Option<[ExprId; 3]>> = Vec::new();
        let mut labels: HashMap<String, Range<usize>> = HashMap::new();
        let mut position_spans: Vec<Vec<Range<usize>>> = Vec::new();
        let mut masses_ok = true;
        for a in &raw.atoms {
            let label = a.label.get_ref();
            match check_label(src, &a.label, &labels) {
                Ok(()) => {
                    labels.insert(label.clone(), a.label.span());
                }
                Err(e) => self.errors.push(e),
            }
            let mass = self.atom_mass(a);
            let (element, mass_da) = self.check(mass).unwrap_or_else(|| {
                masses_ok = false;
                ("X".to_owned(), PLACEHOLDER)
            });
            let context = format!("the position of atom {label}");
            if zmatrix_positions {
                if let Some(position) = &a.position {
                    return Err(self.fail(src.error(
                        position.span(),
                        format!("atom `{label}` has a position, but other atoms have none and the coordinates declare their kind"),
                        "remove every `position` (coordinates by kind place the atoms themselves) or give every atom one",
                    )));
                }
                atoms.push(AtomDef { label: label.clone(), element, mass_da });
                position_spans.push(vec![a.label.span(); 3]);
                continue;
            }
            let position = match &a.position {
                None => {
                    self.errors.push(src.error(
                        a.label.span(),
                        format!("missing position for atom `{label}`"),
                        "add position = [x, y, z], each a number or an expression in quotes",
                    ));
                    None
                }
                Some(position) if position.get_ref().len() != 3 => {
                    self.errors.push(src.error(
                        position.span(),
                        format!(
                            "the position of atom `{label}` has {} components instead of 3",
                            position.get_ref().len()
                        ),
                        "write position = [x, y, z]",
                    ));
                    None
                }
                Some(position) => Some(position),
            };
            let mut xyz = Some([self.graph.zero(); 3]);
            for (axis, component) in position.into_iter().flat_map(|p| p.get_ref().iter().enumerate()) {
                let e = self.value(component, &context);
                match self.check(e) {
                    Some(e) => {
                        let scale = self.graph.constant(length_unit.in_bohr());
                        let scaled = self.graph.mul(scale, e);
                        if let Some(xyz) = xyz.as_mut() {
                            xyz[axis] = scaled;
                        }
                    }
                    None => xyz = None,
                }
            }
            atoms.push(AtomDef { label: label.clone(), element, mass_da });
            positions.push(position.and(xyz));
            position_spans.push(match position {
                Some(p) => p.get_ref().iter().map(|c| c.span()).collect::<Vec<_>>(),
                None => vec![a.label.span(); 3],
            });
        }
        Ok(ReadAtoms { atoms, positions, position_spans, masses_ok, by_kind, zmatrix_positions })
    }

    /// The kinds of coordinates declared by kind, in coordinate order: each checked against its
    /// unit (and a bond angle's range against [0, π]); then the atoms placed by them, or their
    /// explicit positions checked against them.
    fn kinds(
        &mut self,
        raw: &RawDefinition,
        coordinates: &mut [CoordinateDef],
        read: &mut ReadAtoms,
    ) -> Result<Vec<crate::zmatrix::Kind>, Vec<DefinitionError>> {
        let src = self.src;
        let (atoms, zmatrix_positions) = (&read.atoms, read.zmatrix_positions);
        let labels: Vec<&str> = atoms.iter().map(|a| a.label.as_str()).collect();
        let atom_spans: Vec<Range<usize>> = raw.atoms.iter().map(|a| a.label.span()).collect();
        let mut declared = Vec::new();
        for (k, c) in raw.coordinates.iter().enumerate() {
            let kind_value = c.kind.as_ref().expect("every coordinate has a kind");
            let kind = crate::zmatrix::parse_kind(src, kind_value.span(), kind_value.get_ref(), &labels)
                .map_err(|e| self.fail(e))?;
            let is_angle = matches!(coordinates[k].unit, CoordinateUnit::Angle(_));
            if kind.is_angle() != is_angle {
                return Err(self.fail(src.error(
                    c.unit.span(),
                    format!(
                        "coordinate `{}` is declared `{}` but its unit `{}` is {}",
                        coordinates[k].name,
                        kind.name(),
                        c.unit.get_ref(),
                        if is_angle { "an angle" } else { "a length" }
                    ),
                    if kind.is_angle() {
                        "write unit = \"rad\" or \"deg\""
                    } else {
                        "write unit = \"bohr\" or \"angstrom\""
                    },
                )));
            }
            if matches!(kind, crate::zmatrix::Kind::Angle(_)) {
                // A bond angle lies in [0, π]; beyond π it would name the mirror image of a
                // geometry with a smaller angle. With no declared range it gets that one.
                let per_unit = coordinates[k].unit.in_atomic_units();
                let pi = std::f64::consts::PI;
                let (low, high) = coordinates[k].range;
                let slack = 1e-12;
                if c.range.is_some() && (low * per_unit < -slack || high * per_unit > pi + slack) {
                    let span = c.range.as_ref().map_or(kind_value.span(), |r| r.span());
                    return Err(self.fail(src.error(
                        span,
                        format!(
                            "the range [{low:?}, {high:?}] of bond angle `{}` reaches outside [0, π]",
                            coordinates[k].name
                        ),
                        "a bond angle lies in [0, π] (0 to 180°): write range = [0, \"pi\"] (rad) or [0, 180] \
                         (deg), or a narrower interval",
                    )));
                }
                if c.range.is_none() {
                    coordinates[k].range = (0.0, pi / per_unit);
                }
            }
            let c_def = &coordinates[k];
            declared.push(crate::zmatrix::Declared {
                kind,
                span: kind_value.span(),
                var: self.graph.var(&c_def.name),
                reference: c_def.reference.map(|r| r * c_def.unit.in_atomic_units()),
            });
        }
        if zmatrix_positions {
            let built = crate::zmatrix::build_positions(src, &mut self.graph, &labels, &atom_spans, &declared);
            read.positions = built.map_err(|e| self.fail(e))?.into_iter().map(Some).collect();
        } else if let Some(all) = read.positions.iter().copied().collect::<Option<Vec<_>>>() {
            let checked = crate::zmatrix::check_positions(src, &mut self.graph, &all, &declared, &labels);
            checked.map_err(|e| self.fail(e))?;
        }
        Ok(declared.iter().map(|d| d.kind).collect())
    }

    /// The total mass divides every position (the centre-of-mass shift): it must be finite.
    fn check_total_mass(&mut self, read: &ReadAtoms) {
        let (atoms, masses_ok) = (&read.atoms, read.masses_ok);
        let total: f64 = atoms.iter().map(|a| a.mass_da * DALTON_IN_ELECTRON_MASSES).sum();
        if masses_ok && !total.is_finite() {
            self.errors.push(self.src.whole_file(
                format!("the total mass overflows in electron masses ({} atoms)", atoms.len()),
                "give every mass in daltons, e.g. mass = 1.00782503223",
            ));
        }
    }

    /// Every coordinate moves some atom (some position depends on it).
    fn check_coordinates_used(
        &mut self,
        positions: &[[ExprId; 3]],
        coordinates: &[CoordinateDef],
        coordinate_spans: &[Range<usize>],
    ) {
        let roots: Vec<ExprId> = positions.iter().flatten().copied().collect();
        let reachable = self.graph.reachable(&roots);
        for (k, c) in coordinates.iter().enumerate() {
            let used = self.graph.nodes().iter().enumerate().any(|(i, n)| reachable[i] && *n == Node::Var(k as u32));
            if !used {
                self.errors.push(self.src.error(
                    coordinate_spans[k].clone(),
                    format!("no atom position depends on coordinate `{}`", c.name),
                    "use the coordinate in some atom's position, or remove it (a coordinate that moves no atom makes the kinetic metric singular)",
                ));
            }
        }
    }

    /// The `[potential]` table: its unit, its parameters (seen by the potential besides the
    /// coordinates and constants) and the potential, as an expression in hartree or source files.
    fn potential(&mut self, table: &Spanned<RawPotential>) -> ReadPotential {
        let src = self.src;
        let pot = table.get_ref();
        let energy_unit = EnergyUnit::parse(pot.energy_unit.get_ref()).ok_or_else(|| {
            src.error(
                pot.energy_unit.span(),
                format!("unknown energy unit `{}`", pot.energy_unit.get_ref()),
                unit_help(EnergyUnit::SPELLINGS),
            )
        });
        let energy_unit = self.check(energy_unit).unwrap_or(EnergyUnit::Hartree);
        let mut parameters_ok = true;
        for (k, v) in &pot.parameters {
            let declared = self.declare(k, "parameter");
            parameters_ok &= self.check(declared).is_some();
            let value = if v.get_ref().is_finite() {
                *v.get_ref()
            } else {
                parameters_ok = false;
                self.errors.push(src.error(
                    v.span(),
                    format!("non-finite value of parameter `{}`", k.get_ref()),
                    "write a finite number",
                ));
                PLACEHOLDER
            };
            let c = self.graph.constant(value);
            self.names.insert(k.get_ref().clone(), c);
        }
        let potential_scope = self.names.clone();
        let external = self.external_potential(table);
        let external = self.check(external);
        let potential = match (&pot.expression, &external) {
            (Some(expression), _) => {
                let u = self.expression(expression, "the potential");
                self.check(u).map(|u| {
                    let scale = self.graph.constant(energy_unit.in_hartree());
                    self.graph.mul(scale, u)
                })
            }
            (None, Some(Some(_))) => Some(self.graph.constant(0.0)),
            (None, _) => None,
        };
        ReadPotential { energy_unit, parameters_ok, scope: potential_scope, potential, external: external.flatten() }
    }

    /// Every position component that is known now ([`Known`]) is finite.
    fn check_positions_finite(&mut self, read: &ReadAtoms, known: &Known) {
        let src = self.src;
        for (i, xyz) in read.positions.iter().enumerate() {
            for (axis, &e) in xyz.iter().flatten().enumerate() {
                if let Some((v, place)) = known.value(&self.graph, e).filter(|(v, _)| !v.is_finite()) {
                    self.errors.push(src.error(
                        read.position_spans[i][axis].clone(),
                        format!("the {} coordinate of atom `{}` is {v} {place}", ["x", "y", "z"][axis], read.atoms[i].label),
                        "check for a division by zero, the square root or logarithm of a negative number, or a number too large in bohr",
                    ));
                }
            }
        }
    }

    /// The `[dipole]` table, whose first mistake is collected with the others; where the
    /// constants had no problem, every part of it known now ([`Known`]) is finite.
    fn dipole_table(
        &mut self,
        d: &Spanned<RawDipole>,
        atoms: &[AtomDef],
        known: &Known,
        constants_ok: bool,
    ) -> Option<DipoleDef> {
        let src = self.src;
        let read = self.dipole(d, atoms);
        self.check(read).map(|(dipole, spans)| {
                let what = match &dipole {
                    DipoleDef::Components(c) => c.to_vec(),
                    DipoleDef::Charges(c) => c.clone(),
                };
                for (e, span) in what.into_iter().zip(spans).filter(|_| constants_ok) {
                    if let Some((v, place)) = known.value(&self.graph, e).filter(|(v, _)| !v.is_finite()) {
                        self.errors.push(src.error(
                            span,
                            format!("this part of the dipole is {v} {place}"),
                            "check for a division by zero, the logarithm or square root of a negative number, or values too large",
                        ));
                    }
                }
            dipole
        })
    }

    /// The `[dipole]` table: three components with a unit, or one charge per atom. Returns the
    /// expressions (e·bohr, or e) and the place of each in the file.
    fn dipole(
        &mut self,
        raw: &Spanned<RawDipole>,
        atoms: &[AtomDef],
    ) -> Result<(DipoleDef, Vec<Range<usize>>), DefinitionError> {
        let src = self.src;
        let d = raw.get_ref();
        let forms = "write either components = [\"mu_x\", \"mu_y\", \"mu_z\"] with unit = \"debye\" \
                     (or \"e*bohr\", \"e*angstrom\"), or charges = { LABEL = charge, ... } in e";
        for (k, v) in &d.parameters {
            self.declare(k, "dipole parameter")?;
            if !v.get_ref().is_finite() {
                return Err(src.error(
                    v.span(),
                    format!("non-finite value of dipole parameter `{}`", k.get_ref()),
                    "write a finite number",
                ));
            }
            let c = self.graph.constant(*v.get_ref());
            self.names.insert(k.get_ref().clone(), c);
        }
        match (&d.components, &d.charges) {
            (Some(_), Some(_)) => {
                Err(src.error(raw.span(), "the [dipole] table gives both `components` and `charges`", forms))
            }
            (None, None) => {
                Err(src.error(raw.span(), "the [dipole] table gives neither `components` nor `charges`", forms))
            }
            (Some(components), None) => {
                let Some(unit) = &d.unit else {
                    return Err(src.error(
                        components.span(),
                        "the dipole components have no unit",
                        format!("add unit = \"debye\" to the [dipole] table ({})", unit_help(DipoleUnit::SPELLINGS)),
                    ));
                };
                let unit = DipoleUnit::parse(unit.get_ref()).ok_or_else(|| {
                    src.error(
                        unit.span(),
                        format!("unknown dipole unit `{}`", unit.get_ref()),
                        unit_help(DipoleUnit::SPELLINGS),
                    )
                })?;
                let values = components.get_ref();
                if values.len() != 3 {
                    return Err(src.error(
                        components.span(),
                        format!("the dipole has {} components instead of 3", values.len()),
                        "write components = [mu_x, mu_y, mu_z] in the body frame of the positions",
                    ));
                }
                let mut mu = [self.graph.zero(); 3];
                for (axis, v) in values.iter().enumerate() {
                    let context = format!("the dipole's {} component", ["x", "y", "z"][axis]);
                    let e = self.value(v, &context)?;
                    let scale = self.graph.constant(unit.in_e_bohr());
                    mu[axis] = self.graph.mul(scale, e);
                }
                Ok((DipoleDef::Components(mu), values.iter().map(|v| v.span()).collect()))
            }
            (None, Some(charges)) => {
                if let Some(unit) = &d.unit {
                    return Err(src.error(
                        unit.span(),
                        "`unit` is not used with `charges`",
                        "remove it: charges are in units of e, and the positions' length unit is the file's",
                    ));
                }
                let labels: Vec<&str> = atoms.iter().map(|a| a.label.as_str()).collect();
                let mut found: Vec<Option<(ExprId, Range<usize>)>> = vec![None; atoms.len()];
                for (label, v) in charges {
                    let Some(i) = labels.iter().position(|l| *l == label.get_ref()) else {
                        let hint = parse::closest(label.get_ref(), &labels)
                            .map(|s| format!("did you mean `{s}`? "))
                            .unwrap_or_default();
                        return Err(src.error(
                            label.span(),
                            format!("`{}` in the dipole's charges is not an atom", label.get_ref()),
                            format!("{hint}the atoms are: {}", labels.join(", ")),
                        ));
                    };
                    let e = self.value(v, &format!("the charge of atom {}", label.get_ref()))?;
                    found[i] = Some((e, v.span()));
                }
                let missing: Vec<&str> =
                    labels.iter().zip(&found).filter(|(_, f)| f.is_none()).map(|(l, _)| *l).collect();
                if !missing.is_empty() {
                    return Err(src.error(
                        raw.span(),
                        format!("the dipole's charges leave out atom(s) {}", missing.join(", ")),
                        "give every atom a charge in e (0 for an atom that carries none)",
                    ));
                }
                let (charges, spans) = found.into_iter().flatten().unzip();
                Ok((DipoleDef::Charges(charges), spans))
            }
        }
    }

    /// The declared range of a coordinate in its unit, or the default; checked to be an interval
    /// that is also one in atomic units.
    fn range(&self, c: &RawCoordinate, unit: CoordinateUnit) -> Result<(f64, f64), DefinitionError> {
        let src = self.src;
        let Some(range) = &c.range else { return Ok(default_range(unit)) };
        let help = "write range = [low, high] in the coordinate's unit, low < high; numbers, `pi` and \
                    `inf` (e.g. [0, \"pi\"], [0, 180], [-inf, inf])";
        let [low, high] = range.get_ref().as_slice() else {
            return Err(src.error(
                range.span(),
                format!("the range of `{}` has {} values instead of 2", c.name.get_ref(), range.get_ref().len()),
                help,
            ));
        };
        let bound = |v: &Spanned<RawValue>| -> Result<f64, DefinitionError> {
            let x = match v.get_ref() {
                RawValue::Int(i) => *i as f64,
                RawValue::Float(x) => *x,
                RawValue::Expr(text) if text.trim() == "inf" => f64::INFINITY,
                RawValue::Expr(text) if text.trim() == "-inf" => f64::NEG_INFINITY,
                RawValue::Expr(text) => {
                    let mut g = Graph::new();
                    let names = HashMap::new();
                    let library = Library::default();
                    let scope = Scope { names: &names, context: "a range", library: &library, named: true };
                    let e = parse::parse_expression(&mut g, text, &scope)
                        .map_err(|e| src.expression_error(v.span(), text, e))?;
                    g.as_const(e).unwrap_or(f64::NAN)
                }
            };
            if x.is_nan() || (x.is_finite() && !(x * unit.in_atomic_units()).is_finite()) {
                return Err(src.error(
                    v.span(),
                    format!("invalid bound {x:?} in the range of `{}`", c.name.get_ref()),
                    help,
                ));
            }
            Ok(x)
        };
        let (low, high) = (bound(low)?, bound(high)?);
        if low >= high {
            return Err(src.error(
                range.span(),
                format!("the range of `{}` is empty: {low:?} is not below {high:?}", c.name.get_ref()),
                help,
            ));
        }
        Ok((low, high))
    }

    /// Evaluates the constants, each of which may use `pi` and other constants. A constant with
    /// a problem is recorded and bound to a placeholder, so the expressions using it still parse.
    fn resolve_constants(&mut self, constants: &[(Spanned<String>, Spanned<RawValue>)]) {
        let mut pending: Vec<&(Spanned<String>, Spanned<RawValue>)> = constants.iter().collect();
        while !pending.is_empty() {
            let before = pending.len();
            let mut still = Vec::new();
            for entry in pending {
                let (k, v) = entry;
                let uses_unresolved = match v.get_ref() {
                    RawValue::Expr(s) => constants.iter().any(|(other, _)| {
                        !self.names.contains_key(other.get_ref())
                            && other.get_ref() != k.get_ref()
                            && mentions(s, other.get_ref())
                    }),
                    _ => false,
                };
                if uses_unresolved {
                    still.push(entry);
                    continue;
                }
                let e = self.value(v, &format!("constant `{}`", k.get_ref()));
                let value = match self.check(e).map(|e| self.graph.as_const(e)) {
                    Some(Some(value)) => value,
                    Some(None) => {
                        self.errors.push(self.src.error(
                            v.span(),
                            format!("constant `{}` is not a finite number", k.get_ref()),
                            "a constant must evaluate to a finite number from numbers, pi and other constants",
                        ));
                        PLACEHOLDER
                    }
                    None => PLACEHOLDER,
                };
                let c = self.graph.constant(value);
                self.names.insert(k.get_ref().clone(), c);
            }
            if still.len() == before {
                let (k, v) = still[0];
                self.errors.push(self.src.error(
                    v.span(),
                    format!("constant `{}` is defined in terms of itself (a cycle of constants)", k.get_ref()),
                    "define each constant from numbers, pi and constants that do not refer back to it",
                ));
                for (k, _) in still {
                    let c = self.graph.constant(PLACEHOLDER);
                    self.names.insert(k.get_ref().clone(), c);
                }
                break;
            }
            pending = still;
        }
    }

    fn atom_mass(&self, a: &RawAtom) -> Result<(String, f64), DefinitionError> {
        let src = self.src;
        let label = a.label.get_ref();
        let element = match &a.element {
            Some(e) => elements::element(e.get_ref()).map(|el| el.symbol).ok_or_else(|| {
                src.error(
                    e.span(),
                    format!("unknown element `{}`", e.get_ref()),
                    "write the chemical symbol with its usual capitalisation (e.g. \"Cl\"), or give `mass` in Da explicitly",
                )
            }),
            None => elements::element_of_label(label).map(|el| el.symbol).ok_or_else(|| {
                src.error(
                    a.label.span(),
                    format!("cannot tell the element of atom `{label}` from its label"),
                    "add element = \"X\" with the chemical symbol",
                )
            }),
        };
        if a.element.is_some() {
            // An element the user named must exist, even where an explicit mass makes it unneeded.
            element.clone()?;
        }
        if let Some(m) = &a.mass {
            let mass = *m.get_ref();
            if !(mass.is_finite() && mass > 0.0) {
                return Err(src.error(
                    m.span(),
                    format!("the mass of atom `{label}` must be positive and finite, got {mass}"),
                    "give the mass in daltons, e.g. mass = 1.00782503223",
                ));
            }
            if !(mass * DALTON_IN_ELECTRON_MASSES).is_finite() {
                return Err(src.error(
                    m.span(),
                    format!("the mass of atom `{label}` ({mass:?} Da) overflows in electron masses"),
                    "give the mass in daltons, e.g. mass = 1.00782503223",
                ));
            }
            // An explicit mass needs no table, but the element is still needed for output files.
            return Ok((element.unwrap_or("X").to_owned(), mass));
        }
        let symbol = element?;
        let el = elements::element(symbol).expect("found above");
        let isotope = a.isotope.as_ref().map(|i| *i.get_ref());
        let mass = el.mass(isotope).ok_or_else(|| {
            let known: Vec<String> = el.isotopes.iter().map(|(n, _)| n.to_string()).collect();
            src.error(
                a.isotope.as_ref().map_or(a.label.span(), |i| i.span()),
                format!("no mass for isotope {} of {symbol} in rovib's table", isotope.unwrap_or(0)),
                format!("known isotopes of {symbol}: {}; or give `mass` in Da explicitly", known.join(", ")),
            )
        })?;
        Ok((symbol.to_owned(), mass))
    }
}

/// Whether `text` mentions `name` as a whole identifier.
fn mentions(text: &str, name: &str) -> bool {
    text.split(|c: char| !(c.is_ascii_alphanumeric() || c == '_')).any(|w| w == name)
}
