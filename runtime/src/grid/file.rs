//! The grid file: a plain table, one point a line.
//!
//! ```text
//! # comments and blank lines are skipped
//! R[bohr], theta[deg], energy[cm-1], mu_x[debye], mu_y[debye], mu_z[debye]
//! 5.0, 0, -12.5, 0.01, 0, 0.2
//! ...
//! ```
//!
//! The header names 1 to 3 axis columns (`name[unit]`, a length or angle unit), then
//! `energy[unit]`, then optionally all three of `mu_x`, `mu_y`, `mu_z` with a dipole unit.
//! Fields are separated by commas, whitespace or both. The rows list every point of the
//! rectangular grid exactly once, the first axis slowest and the last fastest, each axis's values
//! strictly increasing, at least 4 per axis. Every departure is an error at its line and column.

use std::ops::Range;

use super::spline::{MAX_AXES, TensorSpline};
use crate::diagnostic::{FileError, Source};
use crate::units::{CoordinateUnit, DipoleUnit, EnergyUnit};

/// The dipole columns, in order.
pub const DIPOLE_COLUMNS: [&str; 3] = ["mu_x", "mu_y", "mu_z"];

/// One axis of a grid file as written.
#[derive(Clone, Debug, PartialEq)]
pub struct GridAxis {
    /// The name in the header (a coordinate's name).
    pub name: String,
    /// The unit in the header.
    pub unit: CoordinateUnit,
    /// The header field's byte range in the file.
    pub span: Range<usize>,
}

/// A parsed grid file: the axes and the spline through its points, in atomic units (bohr, rad,
/// hartree, e·bohr). Column 0 is the energy, columns 1 to 3 (if present) μ_x, μ_y, μ_z.
#[derive(Clone, Debug)]
pub struct GridFile {
    /// The axes, in the file's order.
    pub axes: Vec<GridAxis>,
    /// The energy column's unit as written.
    pub energy_unit: EnergyUnit,
    /// Whether the file has the three dipole columns.
    pub dipole: bool,
    /// The spline through the points.
    pub spline: TensorSpline,
}

struct Field<'a> {
    text: &'a str,
    at: usize,
}

/// Fields of one line (separators: commas and whitespace), with their byte offsets in the file.
fn fields(line: &str, start: usize) -> Vec<Field<'_>> {
    let mut out = Vec::new();
    let mut begin = None;
    for (i, c) in line.char_indices().chain(std::iter::once((line.len(), ','))) {
        if c == ',' || c.is_whitespace() {
            if let Some(b) = begin.take() {
                out.push(Field { text: &line[b..i], at: start + b });
            }
        } else if begin.is_none() {
            begin = Some(i);
        }
    }
    out
}

/// Splits `name[unit]`.
fn name_unit(text: &str) -> Option<(&str, &str)> {
    let open = text.find('[')?;
    let unit = text[open + 1..].strip_suffix(']')?;
    (open > 0 && !unit.is_empty()).then(|| (&text[..open], unit))
}

fn spellings<T>(list: &[(&str, T)]) -> String {
    list.iter().map(|(n, _)| format!("`{n}`")).collect::<Vec<_>>().join(", ")
}

/// The header's format, the help of every error about the header.
const FORMAT: &str = "the header is `axis[unit], …, energy[unit]` (1 to 3 axes), optionally followed by \
                      `mu_x[unit], mu_y[unit], mu_z[unit]` (see docs/src/howto/outside-surfaces.md)";

/// How the rows must be ordered, the help of every error about a point's place.
const ORDER: &str = "rows list every point once, the first axis slowest and the last fastest, each axis's values \
                     strictly increasing";

/// The byte range of a field in the file.
fn at(f: &Field<'_>) -> Range<usize> {
    f.at..f.at + f.text.len()
}

/// Parses the grid file `src` (see the module documentation) and builds its spline.
pub fn parse(src: &Source<'_>) -> Result<GridFile, FileError> {
    let mut lines = lines(src.text).into_iter();
    let Some(header) = lines.next() else {
        return Err(src.whole_file("the grid file has no header and no points", FORMAT));
    };
    let header = Header::read(src, &header)?;
    let points = Points::read(src, &header, lines)?;
    let shape = Shape::of(&points.rows, header.dims());
    let knots = knots(src, &header, &points, &shape)?;
    check_rectangular(src, &header, &points, &shape, &knots)?;
    let dims = header.dims();
    let values: Vec<f64> = points.rows.iter().flat_map(|r| r[dims..].iter().copied()).collect();
    let spline = TensorSpline::new(knots, header.columns.len() - dims, &values)
        .map_err(|e| src.whole_file(format!("cannot build the spline: {e}"), "check the grid's values"))?;
    Ok(GridFile { axes: header.axes, energy_unit: header.energy_unit, dipole: header.dipole, spline })
}

/// The lines that hold fields (comments and blank lines skipped), each as its fields.
fn lines(text: &str) -> Vec<Vec<Field<'_>>> {
    let mut lines = Vec::new();
    let mut offset = 0;
    for line in text.split_inclusive('\n') {
        let body = line.split('#').next().unwrap_or("");
        let f = fields(body, offset);
        if !f.is_empty() {
            lines.push(f);
        }
        offset += line.len();
    }
    lines
}

/// The header read: every column's name and field, the axes, the units, and the factor that
/// converts each column to atomic units.
struct Header<'a> {
    /// Every column's name and its field in the header.
    columns: Vec<(&'a str, &'a Field<'a>)>,
    axes: Vec<GridAxis>,
    energy_unit: EnergyUnit,
    dipole: bool,
    /// Atomic units per unit of each column.
    scale: Vec<f64>,
}

impl<'a> Header<'a> {
    /// Reads the header's fields: `name[unit]` each, 1 to [`MAX_AXES`] axes, `energy`, and
    /// the three dipole columns or none.
    fn read(src: &Source<'_>, header: &'a [Field<'a>]) -> Result<Self, FileError> {
        let mut parsed = Vec::new();
        for f in header {
            let Some((name, unit)) = name_unit(f.text) else {
                return Err(src.error(at(f), format!("`{}` is not a column `name[unit]`", f.text), FORMAT));
            };
            parsed.push((name, unit, f));
        }
        let Some(energy) = parsed.iter().position(|(n, _, _)| *n == "energy") else {
            return Err(src.error(at(&header[0]), "the header has no `energy[unit]` column", FORMAT));
        };
        let dims = energy;
        if dims == 0 || dims > MAX_AXES {
            return Err(src.error(
                at(&header[0]),
                format!("the header has {dims} axis columns before `energy`; a grid has 1 to {MAX_AXES}"),
                FORMAT,
            ));
        }
        let axes = axes(src, &parsed[..dims])?;
        let (_, unit, f) = parsed[energy];
        let Some(energy_unit) = EnergyUnit::parse(unit) else {
            return Err(src.error(
                at(f),
                format!("unknown energy unit `{unit}`"),
                format!("use one of {}", spellings(EnergyUnit::SPELLINGS)),
            ));
        };
        let dipole_unit = dipole_unit(src, &parsed[energy + 1..])?;
        let mut scale = vec![energy_unit.in_hartree(); header.len()];
        for (a, axis) in axes.iter().enumerate() {
            scale[a] = axis.unit.in_atomic_units();
        }
        if let Some(u) = dipole_unit {
            scale[dims + 1..].fill(u.in_e_bohr());
        }
        let columns = parsed.iter().map(|&(name, _, f)| (name, f)).collect();
        Ok(Self { columns, axes, energy_unit, dipole: dipole_unit.is_some(), scale })
    }

    /// The number of axes.
    fn dims(&self) -> usize {
        self.axes.len()
    }
}

/// The axis columns of the header (`name`, `unit`, field each): a coordinate unit each, no name
/// twice.
fn axes(src: &Source<'_>, columns: &[(&str, &str, &Field<'_>)]) -> Result<Vec<GridAxis>, FileError> {
    let mut axes = Vec::new();
    for &(name, unit, f) in columns {
        let Some(u) = CoordinateUnit::parse(unit) else {
            return Err(src.error(
                at(f),
                format!("unknown coordinate unit `{unit}` for axis `{name}`"),
                "use a length unit (`bohr`, `angstrom`) or an angle unit (`rad`, `deg`)",
            ));
        };
        if axes.iter().any(|a: &GridAxis| a.name == name) {
            return Err(src.error(at(f), format!("axis `{name}` is named twice"), "name each axis once"));
        }
        axes.push(GridAxis { name: name.to_owned(), unit: u, span: at(f) });
    }
    Ok(axes)
}

/// The columns after `energy`: none, or `mu_x`, `mu_y`, `mu_z` in one dipole unit (returned).
fn dipole_unit(src: &Source<'_>, rest: &[(&str, &str, &Field<'_>)]) -> Result<Option<DipoleUnit>, FileError> {
    match rest {
        [] => Ok(None),
        [x, y, z] if [x.0, y.0, z.0] == DIPOLE_COLUMNS => {
            let mut unit = None;
            for (name, u, f) in rest {
                let Some(u) = DipoleUnit::parse(u) else {
                    return Err(src.error(
                        at(f),
                        format!("unknown dipole unit `{u}` for `{name}`"),
                        format!("use one of {}", spellings(DipoleUnit::SPELLINGS)),
                    ));
                };
                if unit.is_some_and(|v| v != u) {
                    return Err(src.error(at(f), "the dipole columns have different units", "give all three one unit"));
                }
                unit = Some(u);
            }
            Ok(unit)
        }
        _ => Err(src.error(
            at(rest[0].2),
            "after `energy` the header may only have the three columns `mu_x[unit], mu_y[unit], mu_z[unit]`",
            FORMAT,
        )),
    }
}

/// The points: each row's numbers in atomic units, and their fields' offsets in the file.
struct Points {
    rows: Vec<Vec<f64>>,
    places: Vec<Vec<usize>>,
}

impl Points {
    /// Reads the lines after the header: one finite number per column each, at least one line.
    fn read<'a>(
        src: &Source<'_>,
        header: &Header<'_>,
        lines: impl Iterator<Item = Vec<Field<'a>>>,
    ) -> Result<Self, FileError> {
        let columns = header.columns.len();
        let mut rows: Vec<Vec<f64>> = Vec::new();
        let mut places: Vec<Vec<usize>> = Vec::new();
        for line in lines {
            if line.len() != columns {
                let f = line.get(columns).unwrap_or(&line[line.len() - 1]);
                return Err(src.error(
                    at(f),
                    format!("this line has {} fields; the header has {columns} columns", line.len()),
                    "write one number per column on every line",
                ));
            }
            let mut row = Vec::with_capacity(columns);
            for (c, f) in line.iter().enumerate() {
                match f.text.parse::<f64>() {
                    Ok(v) if v.is_finite() => row.push(v * header.scale[c]),
                    _ => {
                        return Err(src.error(
                            at(f),
                            format!("`{}` in column `{}` is not a finite number", f.text, header.columns[c].0),
                            "write every value as a finite decimal number (no NaN or inf: a grid is complete)",
                        ));
                    }
                }
            }
            places.push(line.iter().map(|f| f.at).collect());
            rows.push(row);
        }
        if rows.is_empty() {
            return Err(src.error(
                at(header.columns[0].1),
                "the grid file has a header but no points",
                "add the grid's points",
            ));
        }
        Ok(Self { rows, places })
    }
}

/// The grid's shape as the rows give it: the values per axis and the rows between consecutive
/// values of each axis.
struct Shape {
    counts: [usize; MAX_AXES],
    strides: [usize; MAX_AXES],
    /// The number of points of the rectangular grid.
    total: usize,
}

impl Shape {
    /// Axis lengths, last axis first: how many leading rows (blocks) share the slower axes'
    /// values; the first axis takes as many as the rows need.
    fn of(rows: &[Vec<f64>], dims: usize) -> Self {
        let mut counts = [1usize; MAX_AXES];
        let mut block = 1;
        for a in (1..dims).rev() {
            let mut n = 1;
            while n * block < rows.len() && rows[n * block][..a] == rows[0][..a] {
                n += 1;
            }
            counts[a] = n;
            block *= n;
        }
        counts[0] = rows.len().div_ceil(block);
        let total: usize = counts[..dims].iter().product();
        let mut strides = [0; MAX_AXES];
        let mut s = 1;
        for a in (0..dims).rev() {
            strides[a] = s;
            s *= counts[a];
        }
        Self { counts, strides, total }
    }

    /// Axis `a`'s knot at row `r` of the rectangular grid.
    fn knot(&self, knots: &[Vec<f64>], a: usize, r: usize) -> f64 {
        knots[a][(r / self.strides[a]) % self.counts[a]]
    }

    /// `4 r × 5 theta`: the grid's size by axis.
    fn describe(&self, axes: &[GridAxis]) -> String {
        axes.iter()
            .enumerate()
            .map(|(b, axis)| format!("{} {}", self.counts[b], axis.name))
            .collect::<Vec<_>>()
            .join(" × ")
    }
}

/// Each axis's values, read from the rows where the shape puts them: strictly increasing, at
/// least 4.
fn knots(src: &Source<'_>, header: &Header<'_>, points: &Points, shape: &Shape) -> Result<Vec<Vec<f64>>, FileError> {
    let (rows, scale) = (&points.rows, &header.scale);
    let mut knots: Vec<Vec<f64>> = Vec::new();
    for (a, axis) in header.axes.iter().enumerate() {
        let mut k: Vec<f64> = Vec::with_capacity(shape.counts[a]);
        for i in 0..shape.counts[a] {
            let r = (i * shape.strides[a]).min(rows.len() - 1);
            let v = rows[r][a];
            if let Some(&last) = k.last()
                && v <= last
            {
                return Err(src.error_at_offset(
                    points.places[r][a],
                    format!(
                        "{} = {} follows {} = {}: the values of axis `{}` are {}",
                        axis.name,
                        v / scale[a],
                        axis.name,
                        last / scale[a],
                        axis.name,
                        if v == last { "repeated" } else { "not increasing" }
                    ),
                    ORDER,
                ));
            }
            k.push(v);
        }
        knots.push(k);
    }
    for (axis, k) in header.axes.iter().zip(&knots) {
        if k.len() < 4 {
            return Err(src.error(
                axis.span.clone(),
                format!("axis `{}` has {} values; a cubic spline needs at least 4", axis.name, k.len()),
                "give every axis at least 4 values",
            ));
        }
    }
    Ok(knots)
}

/// Checks that the rows are the points of the rectangular grid of `knots`, each once, in order.
fn check_rectangular(
    src: &Source<'_>,
    header: &Header<'_>,
    points: &Points,
    shape: &Shape,
    knots: &[Vec<f64>],
) -> Result<(), FileError> {
    let (axes, dims, total) = (&header.axes, header.dims(), shape.total);
    for (r, row) in points.rows.iter().enumerate() {
        for a in 0..dims {
            if r >= total || row[a] != shape.knot(knots, a, r) {
                let expected: Vec<String> = if r < total {
                    (0..dims)
                        .map(|b| format!("{} = {}", axes[b].name, shape.knot(knots, b, r) / header.scale[b]))
                        .collect()
                } else {
                    vec!["no more points".into()]
                };
                return Err(src.error_at_offset(
                    points.places[r][a],
                    format!(
                        "point {} is not where a rectangular grid of {} puts it: expected {}",
                        r + 1,
                        shape.describe(axes),
                        expected.join(", ")
                    ),
                    format!("a point is missing, repeated or out of order: {ORDER}"),
                ));
            }
        }
    }
    let rows = points.rows.len();
    if rows < total {
        return Err(src.error_at_offset(
            points.places[rows - 1][0],
            format!("the file ends after {rows} points; a rectangular grid of {} has {total}", shape.describe(axes)),
            format!("points are missing at the end: {ORDER}"),
        ));
    }
    Ok(())
}
