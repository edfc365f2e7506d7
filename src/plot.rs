//! A minimal log-log line plot as SVG, for work-precision diagrams (no plotting dependency).

use std::fmt::Write as _;

/// One line of a plot: a name and its points (x, y), both positive.
pub struct Series {
    /// Legend text.
    pub name: String,
    /// Points; non-positive or non-finite ones are skipped (they have no place on a log axis).
    pub points: Vec<(f64, f64)>,
}

/// One panel: a title, axis labels and lines.
pub struct Panel {
    /// Title above the panel.
    pub title: String,
    /// Label of the x axis.
    pub x_label: String,
    /// Label of the y axis.
    pub y_label: String,
    /// The lines.
    pub series: Vec<Series>,
}

const COLOURS: [&str; 6] = ["#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#8c564b"];
const MARKERS: [&str; 6] = ["circle", "square", "diamond", "triangle", "circle", "square"];
const W: f64 = 520.0;
const H: f64 = 400.0;
const MARGIN_LEFT: f64 = 75.0;
const MARGIN_RIGHT: f64 = 20.0;
const MARGIN_TOP: f64 = 40.0;
const MARGIN_BOTTOM: f64 = 55.0;

fn decades(values: impl Iterator<Item = f64>) -> Option<(i32, i32)> {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for v in values.filter(|v| v.is_finite() && *v > 0.0) {
        lo = lo.min(v.log10());
        hi = hi.max(v.log10());
    }
    if !lo.is_finite() {
        return None;
    }
    let (lo, hi) = (lo.floor() as i32, hi.ceil() as i32);
    Some((lo, if hi == lo { lo + 1 } else { hi }))
}

fn marker(shape: &str, x: f64, y: f64, colour: &str) -> String {
    match shape {
        "square" => format!(r#"<rect x="{:.1}" y="{:.1}" width="7" height="7" fill="{colour}"/>"#, x - 3.5, y - 3.5),
        "diamond" => format!(
            r#"<polygon points="{:.1},{:.1} {:.1},{:.1} {:.1},{:.1} {:.1},{:.1}" fill="{colour}"/>"#,
            x,
            y - 5.0,
            x + 5.0,
            y,
            x,
            y + 5.0,
            x - 5.0,
            y
        ),
        "triangle" => format!(
            r#"<polygon points="{:.1},{:.1} {:.1},{:.1} {:.1},{:.1}" fill="{colour}"/>"#,
            x,
            y - 5.0,
            x + 4.5,
            y + 4.0,
            x - 4.5,
            y + 4.0
        ),
        _ => format!(r#"<circle cx="{x:.1}" cy="{y:.1}" r="3.5" fill="{colour}"/>"#),
    }
}

/// `s` with the characters XML gives a meaning to escaped, for SVG text.
pub(crate) fn escape(s: &str) -> String {
    s.replace('&', "&amp;").replace('<', "&lt;").replace('>', "&gt;")
}

fn panel(svg: &mut String, p: &Panel, x0: f64) {
    let xs = p.series.iter().flat_map(|s| s.points.iter().map(|pt| pt.0));
    let ys = p.series.iter().flat_map(|s| s.points.iter().map(|pt| pt.1));
    let (Some((xlo, xhi)), Some((ylo, yhi))) = (decades(xs), decades(ys)) else {
        let _ = write!(svg, r#"<text x="{:.0}" y="{:.0}">no data</text>"#, x0 + W / 2.0, H / 2.0);
        return;
    };
    let (pw, ph) = (W - MARGIN_LEFT - MARGIN_RIGHT, H - MARGIN_TOP - MARGIN_BOTTOM);
    let px = |x: f64| x0 + MARGIN_LEFT + (x.log10() - f64::from(xlo)) / f64::from(xhi - xlo) * pw;
    let py = |y: f64| MARGIN_TOP + ph - (y.log10() - f64::from(ylo)) / f64::from(yhi - ylo) * ph;
    let (left, right, top, bottom) = (x0 + MARGIN_LEFT, x0 + MARGIN_LEFT + pw, MARGIN_TOP, MARGIN_TOP + ph);
    let _ = write!(svg, r##"<rect x="{left}" y="{top}" width="{pw}" height="{ph}" fill="none" stroke="#444"/>"##);
    let label_step = ((xhi - xlo) as f64 / 8.0).ceil().max(1.0) as i32;
    for d in xlo..=xhi {
        let x = px(10f64.powi(d));
        let _ = write!(svg, r##"<line x1="{x:.1}" y1="{top}" x2="{x:.1}" y2="{bottom}" stroke="#ddd"/>"##);
        if (d - xlo) % label_step == 0 {
            let _ = write!(
                svg,
                r#"<text x="{x:.1}" y="{:.1}" text-anchor="middle" font-size="11">1e{d}</text>"#,
                bottom + 16.0
            );
        }
    }
    let label_step = ((yhi - ylo) as f64 / 10.0).ceil().max(1.0) as i32;
    for d in ylo..=yhi {
        let y = py(10f64.powi(d));
        let _ = write!(svg, r##"<line x1="{left}" y1="{y:.1}" x2="{right}" y2="{y:.1}" stroke="#ddd"/>"##);
        if (d - ylo) % label_step == 0 {
            let _ = write!(
                svg,
                r#"<text x="{:.1}" y="{:.1}" text-anchor="end" font-size="11">1e{d}</text>"#,
                left - 6.0,
                y + 4.0
            );
        }
    }
    let _ = write!(
        svg,
        r#"<text x="{:.1}" y="22" text-anchor="middle" font-size="14" font-weight="bold">{}</text>"#,
        left + pw / 2.0,
        escape(&p.title)
    );
    let _ = write!(
        svg,
        r#"<text x="{:.1}" y="{:.1}" text-anchor="middle" font-size="12">{}</text>"#,
        left + pw / 2.0,
        H - 12.0,
        escape(&p.x_label)
    );
    let _ = write!(
        svg,
        r#"<text transform="translate({:.1},{:.1}) rotate(-90)" text-anchor="middle" font-size="12">{}</text>"#,
        x0 + 16.0,
        top + ph / 2.0,
        escape(&p.y_label)
    );
    for (i, s) in p.series.iter().enumerate() {
        let colour = COLOURS[i % COLOURS.len()];
        let pts: Vec<(f64, f64)> = s
            .points
            .iter()
            .filter(|(x, y)| x.is_finite() && y.is_finite() && *x > 0.0 && *y > 0.0)
            .map(|&(x, y)| (px(x), py(y)))
            .collect();
        if pts.len() > 1 {
            let path: Vec<String> = pts.iter().map(|(x, y)| format!("{x:.1},{y:.1}")).collect();
            let _ = write!(
                svg,
                r#"<polyline points="{}" fill="none" stroke="{colour}" stroke-width="1.5"/>"#,
                path.join(" ")
            );
        }
        for (x, y) in &pts {
            svg.push_str(&marker(MARKERS[i % MARKERS.len()], *x, *y, colour));
        }
        let ly = top + 14.0 + 16.0 * i as f64;
        svg.push_str(&marker(MARKERS[i % MARKERS.len()], right - 120.0, ly - 4.0, colour));
        let _ = write!(svg, r#"<text x="{:.1}" y="{ly:.1}" font-size="11">{}</text>"#, right - 110.0, escape(&s.name));
    }
}

/// Panels side by side, as a standalone SVG document.
pub fn svg(panels: &[Panel]) -> String {
    let width = W * panels.len() as f64;
    let mut s = format!(
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{H}" viewBox="0 0 {width} {H}" font-family="sans-serif">"#
    );
    s.push_str(r#"<rect width="100%" height="100%" fill="white"/>"#);
    for (i, p) in panels.iter().enumerate() {
        panel(&mut s, p, W * i as f64);
    }
    s.push_str("</svg>\n");
    s
}
