//! Log-log line plots as SVG, for work-precision diagrams, drawn with `plotters` (its SVG
//! backend only: no fonts, no system libraries).
//!
//! Measured against the hand-written SVG code this replaced (BENCHMARKS.md; history: "Plots"):
//! 87 lines of code instead of 153 for three small crates (plotters, plotters-backend,
//! plotters-svg) and files about twice as large. The linear-axis ensemble panels
//! (`crate::ensemble::plot`) are drawn with plotters too.

use plotters::coord::Shift;
use plotters::prelude::*;

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

const COLOURS: [RGBColor; 6] = [
    RGBColor(0x1f, 0x77, 0xb4),
    RGBColor(0xd6, 0x27, 0x28),
    RGBColor(0x2c, 0xa0, 0x2c),
    RGBColor(0x94, 0x67, 0xbd),
    RGBColor(0xff, 0x7f, 0x0e),
    RGBColor(0x8c, 0x56, 0x4b),
];
const W: u32 = 520;
const H: u32 = 400;

/// The whole decades that hold `values` (the positive, finite ones), at least one wide.
fn decades(values: impl Iterator<Item = f64>) -> Option<(f64, f64)> {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for v in values.filter(|v| v.is_finite() && *v > 0.0) {
        lo = lo.min(v.log10());
        hi = hi.max(v.log10());
    }
    let (lo, hi) = (lo.floor(), hi.ceil());
    lo.is_finite().then(|| (10f64.powf(lo), 10f64.powf(if hi == lo { lo + 1.0 } else { hi })))
}

/// Draws `p` into `area`; `None` if plotters reports an error (the panel is then left unfinished).
fn panel(area: &DrawingArea<SVGBackend<'_>, Shift>, p: &Panel) -> Option<()> {
    let visible = |s: &Series| -> Vec<(f64, f64)> {
        s.points.iter().copied().filter(|&(x, y)| x.is_finite() && y.is_finite() && x > 0.0 && y > 0.0).collect()
    };
    let all: Vec<(f64, f64)> = p.series.iter().flat_map(visible).collect();
    let (Some(xs), Some(ys)) = (decades(all.iter().map(|pt| pt.0)), decades(all.iter().map(|pt| pt.1))) else {
        return area.draw_text("no data", &("sans-serif", 14).into(), (W as i32 / 2 - 30, H as i32 / 2)).ok();
    };
    let mut chart = ChartBuilder::on(area)
        .caption(&p.title, ("sans-serif", 14))
        .margin(10)
        .x_label_area_size(40)
        .y_label_area_size(65)
        .build_cartesian_2d((xs.0..xs.1).log_scale(), (ys.0..ys.1).log_scale())
        .ok()?;
    chart
        .configure_mesh()
        .x_desc(&p.x_label)
        .y_desc(&p.y_label)
        // Decades print as 1e-7, not 9.999999999999999e-8.
        .x_label_formatter(&|x| format!("{x:.0e}"))
        .y_label_formatter(&|y| format!("{y:.0e}"))
        .max_light_lines(0)
        .draw()
        .ok()?;
    for (i, s) in p.series.iter().enumerate() {
        let colour = COLOURS[i % COLOURS.len()];
        let pts = visible(s);
        chart
            .draw_series(LineSeries::new(pts.clone(), colour.stroke_width(2)))
            .ok()?
            .label(&s.name)
            .legend(move |(x, y)| PathElement::new([(x - 8, y), (x + 8, y)], colour.stroke_width(2)));
        // Markers tell the lines apart where colours do not (print, colour blindness).
        match i % 3 {
            0 => chart.draw_series(pts.iter().map(|&pt| Circle::new(pt, 3, colour.filled()))).ok()?,
            1 => chart.draw_series(pts.iter().map(|&pt| TriangleMarker::new(pt, 4, colour.filled()))).ok()?,
            _ => chart.draw_series(pts.iter().map(|&pt| Cross::new(pt, 3, colour.stroke_width(2)))).ok()?,
        };
    }
    chart.configure_series_labels().background_style(WHITE.mix(0.85)).border_style(BLACK).draw().ok()
}

/// Panels side by side, as a standalone SVG document.
pub fn svg(panels: &[Panel]) -> String {
    let mut out = String::new();
    {
        let n = panels.len().max(1);
        let root = SVGBackend::with_string(&mut out, (W * n as u32, H)).into_drawing_area();
        // Drawing into a string cannot fail for lack of room; a panel that fails is left blank.
        let _ = root.fill(&WHITE);
        for (area, p) in root.split_evenly((1, n)).iter().zip(panels) {
            let _ = panel(area, p);
        }
        let _ = root.present();
    }
    out
}
