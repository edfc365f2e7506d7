//! Special functions built into the expression graph from its operations, so that their
//! derivatives are exact and the lane form needs nothing new: Legendre and associated Legendre
//! polynomials of integer degree and order, expanded by their recurrences.

use crate::expr::{ExprId, Func, Graph};

/// The highest degree of `legendre` and `assoc_legendre`.
pub const MAX_LEGENDRE_DEGREE: u32 = 200;

/// P_l^m(x) for 0 <= m <= l, without the Condon–Shortley phase (as C++17's
/// `std::assoc_legendre`): P_m^m = (2m − 1)!! (1 − x²)^{m/2}, P_{m+1}^m = (2m + 1) x P_m^m,
/// (n − m + 1) P_{n+1}^m = (2n + 1) x P_n^m − (n + m) P_{n−1}^m. With m = 0 it is the Legendre
/// polynomial P_l (Bonnet's recurrence).
pub fn legendre(g: &mut Graph, l: u32, m: u32, x: ExprId) -> ExprId {
    let mut p_mm = g.one();
    if m > 0 {
        let double_factorial: f64 = (1..=m).map(|k| f64::from(2 * k - 1)).product();
        let one = g.one();
        let x2 = g.powi(x, 2);
        let s2 = g.sub(one, x2);
        let root = if m.is_multiple_of(2) {
            g.powi(s2, (m / 2) as i32)
        } else {
            let s = g.call(Func::Sqrt, s2);
            g.powi(s, m as i32)
        };
        let c = g.constant(double_factorial);
        p_mm = g.mul(c, root);
    }
    if l == m {
        return p_mm;
    }
    let c = g.constant(f64::from(2 * m + 1));
    let xc = g.mul(c, x);
    let mut p_next = g.mul(xc, p_mm);
    let mut p_prev = p_mm;
    for n in m + 1..l {
        let a = g.constant(f64::from(2 * n + 1));
        let ax = g.mul(a, x);
        let t1 = g.mul(ax, p_next);
        let b = g.constant(f64::from(n + m));
        let t2 = g.mul(b, p_prev);
        let num = g.sub(t1, t2);
        let d = g.constant(f64::from(n - m + 1));
        let p = g.div(num, d);
        p_prev = p_next;
        p_next = p;
    }
    p_next
}

#[cfg(test)]
mod tests {
    use super::*;

    /// P_l^m at x, evaluated from the graph.
    fn p(l: u32, m: u32, x: f64) -> f64 {
        let mut g = Graph::new();
        let v = g.var("x");
        let e = legendre(&mut g, l, m, v);
        g.eval(&[e], &[x])[0]
    }

    /// Gauss–Legendre nodes and weights of order n (Newton on P_n, from the Chebyshev guesses).
    fn gauss_legendre(n: u32) -> Vec<(f64, f64)> {
        (0..n)
            .map(|i| {
                let mut x = (std::f64::consts::PI * (f64::from(i) + 0.75) / (f64::from(n) + 0.5)).cos();
                let mut dp = 0.0;
                for _ in 0..100 {
                    // P_n and its derivative by the recurrence.
                    let (mut p0, mut p1) = (1.0, x);
                    for k in 1..n {
                        let k = f64::from(k);
                        (p0, p1) = (p1, ((2.0 * k + 1.0) * x * p1 - k * p0) / (k + 1.0));
                    }
                    dp = f64::from(n) * (x * p1 - p0) / (x * x - 1.0);
                    let dx = p1 / dp;
                    x -= dx;
                    if dx.abs() < 1e-16 {
                        break;
                    }
                }
                (x, 2.0 / ((1.0 - x * x) * dp * dp))
            })
            .collect()
    }

    #[test]
    fn low_degrees_equal_their_closed_forms() {
        for &x in &[-1.0, -0.7, -0.2, 0.0, 0.3, 0.9, 1.0] {
            let s = (1.0f64 - x * x).sqrt();
            let closed = [
                (0, 0, 1.0),
                (1, 0, x),
                (2, 0, 0.5 * (3.0 * x * x - 1.0)),
                (3, 0, 0.5 * (5.0 * x * x * x - 3.0 * x)),
                (4, 0, (35.0 * x.powi(4) - 30.0 * x * x + 3.0) / 8.0),
                (5, 0, (63.0 * x.powi(5) - 70.0 * x.powi(3) + 15.0 * x) / 8.0),
                // Without the Condon–Shortley phase.
                (1, 1, s),
                (2, 1, 3.0 * x * s),
                (2, 2, 3.0 * (1.0 - x * x)),
                (3, 1, 1.5 * (5.0 * x * x - 1.0) * s),
                (3, 2, 15.0 * x * (1.0 - x * x)),
                (3, 3, 15.0 * s * s * s),
                (4, 2, 7.5 * (7.0 * x * x - 1.0) * (1.0 - x * x)),
            ];
            for (l, m, want) in closed {
                let got = p(l, m, x);
                assert!((got - want).abs() <= 1e-14 * want.abs().max(1.0), "P_{l}^{m}({x}) = {got}, want {want}");
            }
        }
    }

    /// ∫ P_l^m P_k^m dx over [−1, 1] = 2/(2l+1) · (l+m)!/(l−m)! δ_lk, by a Gauss–Legendre rule
    /// exact for the polynomial integrands (degree ≤ 2·12).
    #[test]
    fn orthogonality_by_quadrature() {
        let rule = gauss_legendre(16);
        assert!((rule.iter().map(|(_, w)| w).sum::<f64>() - 2.0).abs() < 1e-14);
        for m in 0..4 {
            for l in m..12 {
                for k in m..12 {
                    let integral: f64 = rule.iter().map(|&(x, w)| w * p(l, m, x) * p(k, m, x)).sum();
                    let ratio: f64 = (l - m + 1..=l + m).map(f64::from).product();
                    let want = if l == k { 2.0 / f64::from(2 * l + 1) * ratio } else { 0.0 };
                    let scale = 2.0 / f64::from(2 * l + 1) * ratio;
                    assert!((integral - want).abs() <= 1e-12 * scale, "l={l} k={k} m={m}: {integral} vs {want}");
                }
            }
        }
    }
}
