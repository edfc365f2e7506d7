//! Coordinates declared by kind, and the Z-matrix construction of the body-frame positions.
//!
//! A coordinate may say what it is instead of the definition giving atom positions:
//!
//! ```toml
//! [[coordinates]]
//! name = "r1"
//! unit = "angstrom"
//! kind = "distance(O, H1)"      # |x_H1 − x_O|
//! [[coordinates]]
//! name = "alpha"
//! unit = "rad"
//! kind = "angle(H1, O, H2)"     # the angle at O (the middle atom), in [0, π]
//! # kind = "dihedral(H1, O1, O2, H2)": the torsion about O1–O2, in (−π, π], IUPAC sign
//! ```
//!
//! When every coordinate has a `kind` (and no atom a `position`), the generator places the atoms
//! itself, Z-matrix style, in file order ([`build_positions`]); the **body frame** is:
//!
//! * the first atom at the origin;
//! * the second on the +z axis, placed by `distance(second, first)`;
//! * the third in the xz plane with x ≥ 0, placed by a distance to one of the first two and the
//!   angle at that atom with the other;
//! * every later atom `D` by `distance(D, C)`, `angle(D, C, B)` and `dihedral(D, C, B, A)` with
//!   `A`, `B`, `C` placed before it (the natural extension of the reference frame, "NeRF").
//!
//! (The generator then moves the origin to the centre of mass, as for explicit positions.)
//! Because the coordinates are geometric quantities of the atoms, their values as functions of
//! Cartesian positions `q(x)` have closed forms ([`coordinate_of_positions`]): the lab-frame fit
//! needs no iteration, and the potential can be written as a function of Cartesian positions
//! (see [`crate::cartesian`]).
//!
//! The exact set of declarations a Z-matrix needs is required: one distance for the second atom,
//! a distance and an angle for the third, a distance, an angle and a dihedral for every later
//! one (3·NA − 6 coordinates for NA ≥ 3). Anything else is a located error saying which atom
//! lacks what, or which declaration is redundant.

use std::ops::Range;

use crate::definition_error::DefinitionError;
use crate::diagnostic::Source;
use crate::expr::{ExprId, Func, Graph};
use crate::parse;

/// What a coordinate is, with atom indices (file order).
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub enum Kind {
    /// `distance(A, B)`: `|x_B − x_A|`.
    Distance([usize; 2]),
    /// `angle(A, B, C)`: the angle at `B` between `A` and `C`, in `[0, π]`.
    Angle([usize; 3]),
    /// `dihedral(A, B, C, D)`: the torsion of `A–B–C–D` about `B–C`, in `(−π, π]`, positive
    /// when, looking from `B` to `C`, the bond `B–A` turns clockwise onto `C–D` (IUPAC).
    Dihedral([usize; 4]),
}

impl Kind {
    /// The kind's name as written in a definition.
    pub fn name(&self) -> &'static str {
        match self {
            Kind::Distance(_) => "distance",
            Kind::Angle(_) => "angle",
            Kind::Dihedral(_) => "dihedral",
        }
    }

    /// The atoms it names, in the order written.
    pub fn atoms(&self) -> &[usize] {
        match self {
            Kind::Distance(a) => a,
            Kind::Angle(a) => a,
            Kind::Dihedral(a) => a,
        }
    }

    /// Whether a coordinate of this kind is an angle (so needs an angle unit).
    pub fn is_angle(&self) -> bool {
        !matches!(self, Kind::Distance(_))
    }
}

/// The kind names and how many atoms each takes.
pub const KINDS: [(&str, usize); 3] = [("distance", 2), ("angle", 3), ("dihedral", 4)];

const KIND_HELP: &str = "write kind = \"distance(A, B)\", \"angle(A, B, C)\" (the angle at B) or \
                         \"dihedral(A, B, C, D)\" (the torsion about B–C), with atom labels";

/// Parses `text` (the value of `kind` at `span`) against the atom labels.
pub fn parse_kind(src: &Source<'_>, span: Range<usize>, text: &str, labels: &[&str]) -> Result<Kind, DefinitionError> {
    let t = text.trim();
    let (name, rest) = match t.find('(') {
        Some(i) => (t[..i].trim(), &t[i + 1..]),
        None => return Err(src.error(span, format!("`{t}` is not a coordinate kind"), KIND_HELP)),
    };
    let Some(&(name, arity)) = KINDS.iter().find(|(k, _)| *k == name) else {
        let names: Vec<&str> = KINDS.iter().map(|(k, _)| *k).collect();
        let help = match parse::closest(name, &names) {
            Some(c) => format!("did you mean `{c}`? {KIND_HELP}"),
            None => KIND_HELP.to_owned(),
        };
        return Err(src.error(span, format!("unknown coordinate kind `{name}`"), help));
    };
    let Some(args) = rest.trim_end().strip_suffix(')') else {
        return Err(src.error(span, format!("missing `)` in `{t}`"), KIND_HELP));
    };
    let args: Vec<&str> = args.split(',').map(str::trim).collect();
    if args.len() != arity {
        return Err(src.error(span, format!("`{name}` takes {arity} atoms, `{t}` gives {}", args.len()), KIND_HELP));
    }
    let mut atoms = Vec::with_capacity(arity);
    for a in &args {
        let Some(i) = labels.iter().position(|l| l == a) else {
            let help = match parse::closest(a, labels) {
                Some(c) => format!("did you mean `{c}`? the atoms are: {}", labels.join(", ")),
                None => format!("the atoms are: {}", labels.join(", ")),
            };
            return Err(src.error(span, format!("unknown atom `{a}` in `{t}`"), help));
        };
        if atoms.contains(&i) {
            return Err(src.error(span, format!("atom `{a}` appears twice in `{t}`"), "name distinct atoms"));
        }
        atoms.push(i);
    }
    Ok(match name {
        "distance" => Kind::Distance([atoms[0], atoms[1]]),
        "angle" => Kind::Angle([atoms[0], atoms[1], atoms[2]]),
        _ => Kind::Dihedral([atoms[0], atoms[1], atoms[2], atoms[3]]),
    })
}

/// One declared coordinate: its kind, where `kind` is written, and its graph symbol (the
/// coordinate in atomic units).
pub struct Declared {
    /// The kind.
    pub kind: Kind,
    /// Where the `kind` value is in the file.
    pub span: Range<usize>,
    /// The coordinate's graph variable (atomic units).
    pub var: ExprId,
    /// Its reference value in atomic units, if given.
    pub reference: Option<f64>,
}

type V3 = [ExprId; 3];

fn sub3(g: &mut Graph, a: V3, b: V3) -> V3 {
    [0, 1, 2].map(|i| g.sub(a[i], b[i]))
}

fn dot3(g: &mut Graph, a: V3, b: V3) -> ExprId {
    let mut s = g.mul(a[0], b[0]);
    for i in 1..3 {
        let t = g.mul(a[i], b[i]);
        s = g.add(s, t);
    }
    s
}

fn cross3(g: &mut Graph, a: V3, b: V3) -> V3 {
    [(1, 2), (2, 0), (0, 1)].map(|(i, j)| {
        let l = g.mul(a[i], b[j]);
        let r = g.mul(a[j], b[i]);
        g.sub(l, r)
    })
}

fn norm3(g: &mut Graph, a: V3) -> ExprId {
    let d = dot3(g, a, a);
    g.call(Func::Sqrt, d)
}

fn scale3(g: &mut Graph, s: ExprId, a: V3) -> V3 {
    a.map(|c| g.mul(s, c))
}

fn unit3(g: &mut Graph, a: V3) -> V3 {
    let n = norm3(g, a);
    a.map(|c| g.div(c, n))
}

/// The closed form of a coordinate of kind `kind` from atom positions `x` (graph expressions in
/// bohr): the distance, `atan2(|u × v|, u · v)` for an angle (accurate near 0 and π, where
/// `acos` is not), `atan2(|b₂| b₁ · (b₂ × b₃), (b₁ × b₂) · (b₂ × b₃))` for a dihedral.
pub fn coordinate_of_positions(g: &mut Graph, kind: Kind, x: &[V3]) -> ExprId {
    match kind {
        Kind::Distance([a, b]) => {
            let d = sub3(g, x[b], x[a]);
            norm3(g, d)
        }
        Kind::Angle([a, b, c]) => {
            let u = sub3(g, x[a], x[b]);
            let v = sub3(g, x[c], x[b]);
            let w = cross3(g, u, v);
            let s = norm3(g, w);
            let c = dot3(g, u, v);
            g.atan2(s, c)
        }
        Kind::Dihedral([a, b, c, d]) => {
            let b1 = sub3(g, x[b], x[a]);
            let b2 = sub3(g, x[c], x[b]);
            let b3 = sub3(g, x[d], x[c]);
            let n1 = cross3(g, b1, b2);
            let n2 = cross3(g, b2, b3);
            let l2 = norm3(g, b2);
            let t = dot3(g, b1, n2);
            let y = g.mul(l2, t);
            let xx = dot3(g, n1, n2);
            g.atan2(y, xx)
        }
    }
}

/// Builds the uncentred body-frame positions (bohr) of `labels.len()` atoms from the declared
/// coordinates, in the body frame of the module documentation. `atom_spans[i]` locates atom
/// `i`'s label for errors about an atom that cannot be placed.
pub fn build_positions(
    src: &Source<'_>,
    g: &mut Graph,
    labels: &[&str],
    atom_spans: &[Range<usize>],
    declared: &[Declared],
) -> Result<Vec<V3>, DefinitionError> {
    let na = labels.len();
    let mut used = vec![false; declared.len()];
    let zero = g.zero();
    let mut pos: Vec<V3> = vec![[zero; 3]; na];
    // The kinds involving atom `i` and otherwise only atoms before it.
    let find = |used: &[bool], i: usize, pred: &dyn Fn(&Kind) -> bool| -> Option<usize> {
        declared.iter().enumerate().position(|(k, d)| {
            !used[k] && d.kind.atoms().contains(&i) && d.kind.atoms().iter().all(|&a| a <= i) && pred(&d.kind)
        })
    };
    let before = |i: usize| labels[..i].join(", ");
    for i in 1..na {
        let label = labels[i];
        // The distance to an earlier atom.
        let Some(kd) = find(&used, i, &|k| matches!(k, Kind::Distance(_))) else {
            return Err(src.error(
                atom_spans[i].clone(),
                format!("atom `{label}` is not placed: no coordinate is `distance({label}, X)` with X an atom before it"),
                format!(
                    "declare kind = \"distance({label}, X)\" with X one of {} (coordinates by kind place the atoms in file order)",
                    before(i)
                ),
            ));
        };
        used[kd] = true;
        let Kind::Distance(ab) = declared[kd].kind else { unreachable!("found a distance") };
        let c = if ab[0] == i { ab[1] } else { ab[0] };
        let r = declared[kd].var;
        if i == 1 {
            pos[1] = [zero, zero, r];
            continue;
        }
        // The angle at `c` between `i` and an earlier atom `b`.
        let Some(ka) = find(&used, i, &|k| matches!(k, Kind::Angle([x, v, y]) if *v == c && (*x == i || *y == i)))
        else {
            return Err(src.error(
                atom_spans[i].clone(),
                format!(
                    "atom `{label}` is placed at a distance from `{}` but no coordinate is `angle({label}, {}, X)` with X an atom before it",
                    labels[c], labels[c]
                ),
                format!(
                    "declare kind = \"angle({label}, {}, X)\" with X one of {} other than {} (the angle's middle atom is the one `{label}` is bonded to)",
                    labels[c],
                    before(i),
                    labels[c]
                ),
            ));
        };
        used[ka] = true;
        let Kind::Angle([x, _, y]) = declared[ka].kind else { unreachable!("found an angle") };
        let b = if x == i { y } else { x };
        let theta = declared[ka].var;
        let (s, co) = (g.call(Func::Sin, theta), g.call(Func::Cos, theta));
        let rs = g.mul(r, s);
        let rc = g.mul(r, co);
        if i == 2 {
            // c and b are the first two atoms: the axis from c to b is ±z.
            let z = if b > c { g.add(pos[c][2], rc) } else { g.sub(pos[c][2], rc) };
            pos[2] = [rs, zero, z];
            continue;
        }
        // The dihedral i–c–b–a (or a–b–c–i).
        let Some(kt) = find(&used, i, &|k| {
            matches!(k, Kind::Dihedral([p, q, s, t])
                if (*p == i && *q == c && *s == b) || (*t == i && *s == c && *q == b))
        }) else {
            return Err(src.error(
                atom_spans[i].clone(),
                format!(
                    "atom `{label}` is placed by distance and angle `{}`–`{}` but no coordinate is `dihedral({label}, {}, {}, X)` with X an atom before it",
                    labels[c], labels[b], labels[c], labels[b]
                ),
                format!(
                    "declare kind = \"dihedral({label}, {}, {}, X)\" with X one of {} (a Z-matrix places every atom after the third by a distance, an angle and a dihedral)",
                    labels[c],
                    labels[b],
                    before(i)
                ),
            ));
        };
        used[kt] = true;
        let Kind::Dihedral(d4) = declared[kt].kind else { unreachable!("found a dihedral") };
        let a = if d4[0] == i { d4[3] } else { d4[0] };
        let phi = declared[kt].var;
        // NeRF: bc along b → c, n normal to the plane a, b, c, m = n × bc.
        if let Some(err) = collinear_at_reference(src, g, &pos, [a, b, c], declared, &declared[kt], labels) {
            return Err(err);
        }
        let bc_raw = sub3(g, pos[c], pos[b]);
        let bc = unit3(g, bc_raw);
        let ab = sub3(g, pos[b], pos[a]);
        let n_raw = cross3(g, ab, bc);
        let n = unit3(g, n_raw);
        let m = cross3(g, n, bc);
        let (sp, cp) = (g.call(Func::Sin, phi), g.call(Func::Cos, phi));
        let along = g.neg(rc);
        let across = g.mul(rs, cp);
        let out = g.mul(rs, sp);
        let t1 = scale3(g, along, bc);
        let t2 = scale3(g, across, m);
        let t3 = scale3(g, out, n);
        pos[i] = [0, 1, 2].map(|k| {
            let s = g.add(pos[c][k], t1[k]);
            let s = g.add(s, t2[k]);
            g.add(s, t3[k])
        });
    }
    if let Some(k) = used.iter().position(|u| !u) {
        let d = &declared[k];
        let names: Vec<&str> = d.kind.atoms().iter().map(|&a| labels[a]).collect();
        let last = *d.kind.atoms().iter().max().expect("kinds name atoms");
        return Err(src.error(
            d.span.clone(),
            format!(
                "`{}({})` is not needed to place the atoms: atom `{}` is already placed by other coordinates",
                d.kind.name(),
                names.join(", "),
                labels[last]
            ),
            "a Z-matrix places the 2nd atom by a distance, the 3rd by a distance and an angle, every later one \
             by a distance, an angle and a dihedral to atoms before it (3·atoms − 6 coordinates); remove this one \
             or change the others",
        ));
    }
    Ok(pos)
}

/// An error if the three atoms a dihedral turns about are collinear at the reference geometry
/// (the dihedral is undefined there and so is the atom it places).
fn collinear_at_reference(
    src: &Source<'_>,
    g: &mut Graph,
    pos: &[V3],
    [a, b, c]: [usize; 3],
    declared: &[Declared],
    dihedral: &Declared,
    labels: &[&str],
) -> Option<DefinitionError> {
    let q: Vec<f64> = declared.iter().map(|d| d.reference).collect::<Option<Vec<f64>>>()?;
    // Graph variable k is coordinate k; evaluate the three positions at the reference.
    let mut vars = vec![0.0; g.var_count()];
    for (d, &v) in declared.iter().zip(&q) {
        if let crate::expr::Node::Var(k) = g.node(d.var) {
            vars[k as usize] = v;
        }
    }
    let roots: Vec<ExprId> = [a, b, c].iter().flat_map(|&i| pos[i]).collect();
    let x = g.eval(&roots, &vars);
    let p = |i: usize| [x[3 * i], x[3 * i + 1], x[3 * i + 2]];
    let (pa, pb, pc) = (p(0), p(1), p(2));
    let u = [pa[0] - pb[0], pa[1] - pb[1], pa[2] - pb[2]];
    let v = [pc[0] - pb[0], pc[1] - pb[1], pc[2] - pb[2]];
    let w = [u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]];
    let norm = |z: [f64; 3]| (z[0] * z[0] + z[1] * z[1] + z[2] * z[2]).sqrt();
    let sin = norm(w) / (norm(u) * norm(v));
    (sin < 1e-8 || !sin.is_finite()).then(|| {
        src.error(
            dihedral.span.clone(),
            format!(
                "the dihedral about `{}`–`{}` is undefined at the reference geometry: `{}`, `{}`, `{}` are collinear there",
                labels[b], labels[c], labels[a], labels[b], labels[c]
            ),
            "choose a reference where they are bent, or place this atom from another non-collinear triple \
             (a linear chain of four or more atoms cannot be built from distances, angles and dihedrals at linear)",
        )
    })
}

/// Checks explicit positions against declared kinds: at the reference geometry and at points
/// around it (each coordinate moved by ±0.05 in atomic units, and all together), the closed
/// form of every kind evaluated on the positions must give the coordinate back (angles modulo
/// 2π), else a located error at the first kind that disagrees.
pub fn check_positions(
    src: &Source<'_>,
    g: &mut Graph,
    positions: &[V3],
    declared: &[Declared],
    labels: &[&str],
) -> Result<(), DefinitionError> {
    let closed: Vec<ExprId> = declared.iter().map(|d| coordinate_of_positions(g, d.kind, positions)).collect();
    let vars: Vec<u32> = declared
        .iter()
        .map(|d| match g.node(d.var) {
            crate::expr::Node::Var(k) => k,
            _ => unreachable!("a coordinate's symbol is its variable"),
        })
        .collect();
    let Some(reference) = declared.iter().map(|d| d.reference).collect::<Option<Vec<f64>>>() else {
        return Err(src.error(
            declared[0].span.clone(),
            "coordinates with a kind and explicit positions need a reference geometry (to check that they agree)",
            "give every coordinate a `reference`, or remove the atoms' positions to let the generator place the atoms",
        ));
    };
    let n = declared.len();
    let mut points = vec![reference.clone()];
    for k in 0..n {
        for s in [-0.05, 0.05] {
            let mut p = reference.clone();
            p[k] += s;
            points.push(p);
        }
    }
    points.push(reference.iter().enumerate().map(|(k, r)| r + 0.03 * (1.0 + k as f64 * 0.37).sin()).collect());
    let nv = g.var_count();
    for p in &points {
        let mut x = vec![0.0; nv];
        for (k, &v) in vars.iter().enumerate() {
            x[v as usize] = p[k];
        }
        let got = g.eval(&closed, &x);
        for (k, d) in declared.iter().enumerate() {
            let mut diff = got[k] - p[k];
            if d.kind.is_angle() {
                diff -= (diff / std::f64::consts::TAU).round() * std::f64::consts::TAU;
            }
            // Angles at exactly 0 or π and lengths at 0 are where the closed forms fold; the
            // test points stay away from them only if the reference does, so allow the fold.
            let is_angle = matches!(d.kind, Kind::Angle(_));
            let sum = got[k] + p[k];
            let folded = is_angle && (sum.abs() < 1e-9 || (sum - std::f64::consts::TAU).abs() < 1e-9);
            let agrees = diff.abs() <= 1e-9 * (1.0 + p[k].abs());
            if !agrees && !folded {
                let names: Vec<&str> = d.kind.atoms().iter().map(|&a| labels[a]).collect();
                return Err(src.error(
                    d.span.clone(),
                    format!(
                        "the positions give `{}({})` = {} but the coordinate is {} (atomic units) at q = {p:?}",
                        d.kind.name(),
                        names.join(", "),
                        got[k],
                        p[k]
                    ),
                    "make the kind name the atoms whose distance, angle or dihedral the coordinate is (the middle atom of an angle is its vertex), or correct the positions",
                ));
            }
        }
    }
    Ok(())
}
