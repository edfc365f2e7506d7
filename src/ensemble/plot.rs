//! Linear-axis SVG panels for ensembles: means with ± one standard error as a band, and
//! histograms as bars. (`crate::plot` draws log-log work-precision diagrams; ensemble means
//! can be negative or zero, so they need linear axes.)

use crate::plot::escape;
use std::fmt::Write as _;

/// What one panel shows.
pub enum Content {
    /// A line `(x, y)` with a band `y ± e`.
    Band(Vec<(f64, f64, f64)>),
    /// Bars: `(low edge, high edge, height)`.
    Bars(Vec<(f64, f64, f64)>),
}

/// One panel.
pub struct Panel {
    /// Title.
    pub title: String,
    /// x-axis label.
    pub x_label: String,
    /// y-axis label.
    pub y_label: String,
    /// The data.
    pub content: Content,
}

const W: f64 = 420.0;
const H: f64 = 300.0;
const LEFT: f64 = 80.0;
const RIGHT: f64 = 15.0;
const TOP: f64 = 35.0;
const BOTTOM: f64 = 50.0;
const COLUMNS: usize = 3;

/// A tick label for `v` on an axis whose ticks are `step` apart: as many digits as tell
/// neighbouring ticks apart (a mean that barely moves needs many).
fn tick(v: f64, step: f64) -> String {
    if v == 0.0 || !step.is_finite() || step <= 0.0 {
        return "0".into();
    }
    let magnitude = v.abs().log10().floor();
    let resolution = step.log10().floor();
    if (-2.0..4.0).contains(&magnitude) {
        let decimals = (-resolution + 1.0).clamp(0.0, 15.0) as usize;
        format!("{v:.decimals$}")
    } else {
        let digits = (magnitude - resolution + 1.0).clamp(1.0, 15.0) as usize;
        format!("{v:.digits$e}")
    }
}

/// `[lo, hi]` widened a little, and never empty.
fn range(values: impl Iterator<Item = f64>, padding: f64) -> Option<(f64, f64)> {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for v in values.filter(|v| v.is_finite()) {
        lo = lo.min(v);
        hi = hi.max(v);
    }
    if !lo.is_finite() {
        return None;
    }
    if hi - lo <= 1e-12 * hi.abs().max(lo.abs()).max(1e-300) {
        let pad = if lo == 0.0 { 1.0 } else { 1e-6 * lo.abs() };
        return Some((lo - pad, hi + pad));
    }
    let pad = padding * (hi - lo);
    Some((lo - pad, hi + pad))
}

fn panel(svg: &mut String, p: &Panel, x0: f64, y0: f64) {
    let (xs, ys): (Vec<f64>, Vec<f64>) = match &p.content {
        Content::Band(v) => {
            (v.iter().map(|a| a.0).collect(), v.iter().flat_map(|a| [a.1 - a.2, a.1 + a.2, a.1]).collect())
        }
        Content::Bars(v) => (v.iter().flat_map(|a| [a.0, a.1]).collect(), v.iter().map(|a| a.2).chain([0.0]).collect()),
    };
    let (pw, ph) = (W - LEFT - RIGHT, H - TOP - BOTTOM);
    let (left, top) = (x0 + LEFT, y0 + TOP);
    let _ = write!(
        svg,
        r#"<text x="{:.1}" y="{:.1}" text-anchor="middle" font-size="13" font-weight="bold">{}</text>"#,
        left + pw / 2.0,
        y0 + 20.0,
        escape(&p.title)
    );
    let (Some((xlo, xhi)), Some((ylo, yhi))) = (range(xs.into_iter(), 0.0), range(ys.into_iter(), 0.05)) else {
        let _ = write!(svg, r#"<text x="{:.1}" y="{:.1}">no data</text>"#, left + 10.0, top + ph / 2.0);
        return;
    };
    // Bars stand on zero.
    let ylo = if matches!(p.content, Content::Bars(_)) { 0.0 } else { ylo };
    let px = |x: f64| left + (x - xlo) / (xhi - xlo) * pw;
    let py = |y: f64| top + ph - (y - ylo) / (yhi - ylo) * ph;
    let _ = write!(svg, r##"<rect x="{left}" y="{top}" width="{pw}" height="{ph}" fill="none" stroke="#444"/>"##);
    for i in 0..=4 {
        let f = f64::from(i) / 4.0;
        let (x, y) = (xlo + f * (xhi - xlo), ylo + f * (yhi - ylo));
        let _ = write!(
            svg,
            r#"<text x="{:.1}" y="{:.1}" text-anchor="middle" font-size="10">{}</text>"#,
            px(x),
            top + ph + 14.0,
            tick(x, (xhi - xlo) / 4.0)
        );
        let _ = write!(
            svg,
            r#"<text x="{:.1}" y="{:.1}" text-anchor="end" font-size="10">{}</text>"#,
            left - 4.0,
            py(y) + 3.0,
            tick(y, (yhi - ylo) / 4.0)
        );
    }
    let _ = write!(
        svg,
        r#"<text x="{:.1}" y="{:.1}" text-anchor="middle" font-size="11">{}</text>"#,
        left + pw / 2.0,
        y0 + H - 12.0,
        escape(&p.x_label)
    );
    let _ = write!(
        svg,
        r#"<text transform="translate({:.1},{:.1}) rotate(-90)" text-anchor="middle" font-size="11">{}</text>"#,
        x0 + 14.0,
        top + ph / 2.0,
        escape(&p.y_label)
    );
    match &p.content {
        Content::Band(v) => {
            let finite: Vec<&(f64, f64, f64)> = v.iter().filter(|a| a.0.is_finite() && a.1.is_finite()).collect();
            let upper: Vec<String> =
                finite.iter().map(|a| format!("{:.1},{:.1}", px(a.0), py(a.1 + a.2.abs()))).collect();
            let lower: Vec<String> =
                finite.iter().rev().map(|a| format!("{:.1},{:.1}", px(a.0), py(a.1 - a.2.abs()))).collect();
            if finite.iter().all(|a| a.2.is_finite()) && !finite.is_empty() {
                let _ = write!(
                    svg,
                    r##"<polygon points="{} {}" fill="#1f77b4" fill-opacity="0.25" stroke="none"/>"##,
                    upper.join(" "),
                    lower.join(" ")
                );
            }
            let line: Vec<String> = finite.iter().map(|a| format!("{:.1},{:.1}", px(a.0), py(a.1))).collect();
            let _ = write!(
                svg,
                r##"<polyline points="{}" fill="none" stroke="#1f77b4" stroke-width="1.5"/>"##,
                line.join(" ")
            );
        }
        Content::Bars(v) => {
            for &(lo, hi, h) in v {
                if h.is_finite() && h > 0.0 {
                    let _ = write!(
                        svg,
                        r##"<rect x="{:.1}" y="{:.1}" width="{:.1}" height="{:.1}" fill="#d62728" fill-opacity="0.7"/>"##,
                        px(lo),
                        py(h),
                        (px(hi) - px(lo)).max(0.5),
                        py(0.0) - py(h)
                    );
                }
            }
        }
    }
}

/// The panels in a grid of up to three columns, as a standalone SVG document.
pub fn svg(panels: &[Panel]) -> String {
    let columns = panels.len().clamp(1, COLUMNS);
    let rows = panels.len().div_ceil(COLUMNS).max(1);
    let (width, height) = (W * columns as f64, H * rows as f64);
    let mut s = format!(
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{height}" viewBox="0 0 {width} {height}" font-family="sans-serif">"#
    );
    s.push_str(r#"<rect width="100%" height="100%" fill="white"/>"#);
    if panels.is_empty() {
        s.push_str(
            r#"<text x="20" y="40" font-size="13">nothing to plot: the scene's [statistics] asks for none</text>"#,
        );
    }
    for (i, p) in panels.iter().enumerate() {
        panel(&mut s, p, W * (i % COLUMNS) as f64, H * (i / COLUMNS) as f64);
    }
    s.push_str("</svg>\n");
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ticks_have_the_digits_that_tell_them_apart() {
        assert_eq!(tick(8.7751234, 2.5e-5), "8.775123");
        assert_eq!(tick(2500.0, 2500.0), "2500");
        assert_eq!(tick(4.5691e-3, 1e-9), "4.5691000e-3");
        assert_eq!(tick(0.0, 1.0), "0");
        assert_eq!(tick(-1.5, 0.25), "-1.50");
    }
}
