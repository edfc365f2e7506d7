//! Tensor-product cubic splines over a rectangular grid in 1, 2 or 3 dimensions.
//!
//! Each axis has its own knots (uniform or not, at least 4, strictly increasing). Along an axis
//! the spline is the **not-a-knot** cubic interpolant (the third derivative is continuous at the
//! second and the second-to-last knot), so a cubic polynomial is reproduced exactly and the error
//! is O(h⁴) up to the edges. The surface is the tensor product: in every cell a polynomial of
//! degree 3 in each coordinate, C² across the knots.
//!
//! Representation: along one axis, on `[x_i, x_{i+1}]` with `h = x_{i+1} − x_i`,
//! `A = (x_{i+1} − x)/h`, `B = 1 − A`,
//! `S(x) = A y_i + B y_{i+1} + (A³ − A) h²/6 M_i + (B³ − B) h²/6 M_{i+1}` where `M = L y` are the
//! second derivatives at the knots (`L` from the not-a-knot system, computed once per axis). The
//! tensor product keeps, at every node, the 2^D tables obtained by applying `L` along any subset
//! of the axes (the value, ∂²/∂x², ∂²/∂y², ∂⁴/∂x²∂y², …); a point needs the 4^D products of
//! the per-axis weights with those tables at the cell's corners. The gradient differentiates the
//! weights, so it is the exact derivative of the interpolant. Evaluation allocates nothing.

use nalgebra::DMatrix;

/// The largest number of axes.
pub const MAX_AXES: usize = 3;

/// What a point outside the grid's box gives.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub enum Outside {
    /// NaN for the value and every derivative (the caller reports it).
    Error,
    /// The polynomial of the nearest edge cell, continued (C² at the edge).
    Extrapolate,
}

/// Why knots or values cannot make a spline.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum SplineError {
    /// No axes, or more than [`MAX_AXES`].
    #[error("a grid has 1 to {MAX_AXES} axes, not {0}")]
    Axes(usize),
    /// An axis with fewer than 4 knots (a not-a-knot cubic needs 4).
    #[error("axis {axis} has {count} values; a cubic spline needs at least 4")]
    TooFewKnots {
        /// The axis's index.
        axis: usize,
        /// How many it has.
        count: usize,
    },
    /// Knots that are not finite and strictly increasing.
    #[error("the values of axis {axis} are not finite and strictly increasing at index {index}")]
    Knots {
        /// The axis's index.
        axis: usize,
        /// The first bad index.
        index: usize,
    },
    /// Not one value per node and column, or a value that is not finite.
    #[error("{0}")]
    Values(String),
}

/// A cubic spline surface with `columns` values per node (an energy, dipole components, …).
#[derive(Clone, Debug)]
pub struct TensorSpline {
    knots: Vec<Vec<f64>>,
    columns: usize,
    /// Per node (row-major, last axis fastest): for each of the 2^D tables, every column.
    tables: Vec<f64>,
    strides: [usize; MAX_AXES],
}

impl TensorSpline {
    /// The spline through `values` at the nodes of the grid `knots[0] × knots[1] × …`:
    /// `values[node * columns + c]`, nodes in row-major order (the last axis fastest).
    pub fn new(knots: Vec<Vec<f64>>, columns: usize, values: &[f64]) -> Result<Self, SplineError> {
        let d = knots.len();
        if d == 0 || d > MAX_AXES {
            return Err(SplineError::Axes(d));
        }
        for (axis, k) in knots.iter().enumerate() {
            if k.len() < 4 {
                return Err(SplineError::TooFewKnots { axis, count: k.len() });
            }
            if let Some(index) = (0..k.len()).find(|&i| !k[i].is_finite() || (i > 0 && k[i] <= k[i - 1])) {
                return Err(SplineError::Knots { axis, index });
            }
        }
        let nodes: usize = knots.iter().map(Vec::len).product();
        if columns == 0 || values.len() != nodes * columns {
            return Err(SplineError::Values(format!("{} values for {nodes} nodes × {columns} columns", values.len())));
        }
        if values.iter().any(|v| !v.is_finite()) {
            return Err(SplineError::Values("a value is not finite".into()));
        }
        let mut strides = [0; MAX_AXES];
        let mut s = 1;
        for a in (0..d).rev() {
            strides[a] = s;
            s *= knots[a].len();
        }
        let masks = 1usize << d;
        let width = masks * columns;
        let mut tables = vec![0.0; nodes * width];
        for node in 0..nodes {
            tables[node * width..node * width + columns].copy_from_slice(&values[node * columns..(node + 1) * columns]);
        }
        let operators: Vec<DMatrix<f64>> = knots.iter().map(|k| second_derivative_operator(k)).collect();
        // Table `mask` is table `mask − bit` with L applied along the axis of `bit`, its highest bit.
        for mask in 1..masks {
            let axis = usize::BITS as usize - 1 - mask.leading_zeros() as usize;
            let from = mask & !(1 << axis);
            let n = knots[axis].len();
            let stride = strides[axis];
            let mut line = vec![0.0; n];
            for start in (0..nodes).filter(|node| (node / stride) % n == 0) {
                for c in 0..columns {
                    for (i, y) in line.iter_mut().enumerate() {
                        *y = tables[(start + i * stride) * width + from * columns + c];
                    }
                    let m = &operators[axis] * nalgebra::DVector::from_column_slice(&line);
                    for (i, v) in m.iter().enumerate() {
                        tables[(start + i * stride) * width + mask * columns + c] = *v;
                    }
                }
            }
        }
        Ok(Self { knots, columns, tables, strides })
    }

    /// The number of axes.
    pub fn axes(&self) -> usize {
        self.knots.len()
    }

    /// The knots of axis `a`.
    pub fn knots(&self, a: usize) -> &[f64] {
        &self.knots[a]
    }

    /// The number of values per node.
    pub fn columns(&self) -> usize {
        self.columns
    }

    /// Whether `x` (the first [`TensorSpline::axes`] entries) is inside the grid's box (edges
    /// included).
    pub fn contains(&self, x: &[f64; MAX_AXES]) -> bool {
        self.knots.iter().enumerate().all(|(a, k)| x[a] >= k[0] && x[a] <= k[k.len() - 1])
    }

    /// Column `column`'s value at `x` into the return value and its gradient into `grad`
    /// (entries past the axis count are set to zero). Outside the box: see [`Outside`].
    pub fn evaluate(&self, column: usize, x: &[f64; MAX_AXES], outside: Outside, grad: &mut [f64; MAX_AXES]) -> f64 {
        *grad = [0.0; MAX_AXES];
        let d = self.knots.len();
        if outside == Outside::Error && !self.contains(x) {
            *grad = [f64::NAN; MAX_AXES];
            return f64::NAN;
        }
        let mut weights = [[0.0; 4]; MAX_AXES];
        let mut slopes = [[0.0; 4]; MAX_AXES];
        let mut base = 0;
        for a in 0..d {
            let k = &self.knots[a];
            // The cell [k_i, k_{i+1}] holding x (the edge cell outside the box).
            let i = k.partition_point(|&v| v <= x[a]).clamp(1, k.len() - 1) - 1;
            let h = k[i + 1] - k[i];
            let p = (k[i + 1] - x[a]) / h;
            let q = 1.0 - p;
            weights[a] = [p, q, (p * p * p - p) * h * h / 6.0, (q * q * q - q) * h * h / 6.0];
            slopes[a] = [-1.0 / h, 1.0 / h, -(3.0 * p * p - 1.0) * h / 6.0, (3.0 * q * q - 1.0) * h / 6.0];
            base += i * self.strides[a];
        }
        let width = (1 << d) * self.columns;
        let mut value = 0.0;
        for term in 0..(1usize << (2 * d)) {
            let mut node = base;
            let mut mask = 0;
            let mut w = [1.0; MAX_AXES + 1];
            let mut parts = [0.0; MAX_AXES];
            let mut dparts = [0.0; MAX_AXES];
            for a in 0..d {
                let choice = (term >> (2 * a)) & 3;
                node += (choice & 1) * self.strides[a];
                mask |= (choice >> 1) << a;
                parts[a] = weights[a][choice];
                dparts[a] = slopes[a][choice];
                w[0] *= parts[a];
            }
            let t = self.tables[node * width + mask * self.columns + column];
            value += w[0] * t;
            for g in 0..d {
                let mut prod = dparts[g];
                for a in (0..d).filter(|&a| a != g) {
                    prod *= parts[a];
                }
                grad[g] += prod * t;
            }
        }
        value
    }
}

/// The matrix `L` with `M = L y`: the not-a-knot spline's second derivatives at the knots from
/// the values there.
fn second_derivative_operator(x: &[f64]) -> DMatrix<f64> {
    let n = x.len();
    let h: Vec<f64> = x.windows(2).map(|w| w[1] - w[0]).collect();
    let mut a = DMatrix::zeros(n, n);
    let mut b = DMatrix::zeros(n, n);
    // Continuity of S''' at x_1 and at x_{n−2}.
    a[(0, 0)] = h[1];
    a[(0, 1)] = -(h[0] + h[1]);
    a[(0, 2)] = h[0];
    a[(n - 1, n - 3)] = h[n - 2];
    a[(n - 1, n - 2)] = -(h[n - 3] + h[n - 2]);
    a[(n - 1, n - 1)] = h[n - 3];
    // Continuity of S' at the interior knots.
    for i in 1..n - 1 {
        a[(i, i - 1)] = h[i - 1];
        a[(i, i)] = 2.0 * (h[i - 1] + h[i]);
        a[(i, i + 1)] = h[i];
        b[(i, i - 1)] = 6.0 / h[i - 1];
        b[(i, i)] = -6.0 / h[i] - 6.0 / h[i - 1];
        b[(i, i + 1)] = 6.0 / h[i];
    }
    // Strictly increasing knots make the system regular (the not-a-knot interpolant is unique).
    a.lu().solve(&b).unwrap_or_else(|| DMatrix::from_element(n, n, f64::NAN))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_cubic_through_four_points() {
        let f = |x: f64| 1.0 - 2.0 * x + 0.5 * x * x - 0.25 * x * x * x;
        let knots = vec![0.0, 0.7, 1.1, 2.0];
        let values: Vec<f64> = knots.iter().map(|&x| f(x)).collect();
        let s = TensorSpline::new(vec![knots], 1, &values).unwrap();
        let mut g = [0.0; 3];
        for x in [0.1, 0.9, 1.7, 2.5] {
            let v = s.evaluate(0, &[x, 0.0, 0.0], Outside::Extrapolate, &mut g);
            assert!((v - f(x)).abs() < 1e-13, "{x}: {v} vs {}", f(x));
            assert!((g[0] - (-2.0 + x - 0.75 * x * x)).abs() < 1e-12);
        }
        assert!(s.evaluate(0, &[2.5, 0.0, 0.0], Outside::Error, &mut g).is_nan() && g[0].is_nan());
    }
}
