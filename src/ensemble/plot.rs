//! Linear-axis SVG panels for ensembles, drawn with `plotters`: means with ± one standard
//! error as a band, and histograms as bars. (`crate::plot` draws log-log work-precision
//! diagrams; ensemble means can be negative or zero, so they need linear axes.)
//!
//! Measured against the hand-written SVG this replaced (BENCHMARKS.md; history: "Plots"): see
//! there for lines of code and file sizes.

#![cfg_attr(not(feature = "svg"), allow(dead_code))]

#[cfg(feature = "svg")]
use plotters::coord::Shift;
#[cfg(feature = "svg")]
use plotters::prelude::*;

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

const W: u32 = 420;
const H: u32 = 300;
const COLUMNS: usize = 3;
#[cfg(feature = "svg")]
const BAND: RGBColor = RGBColor(0x1f, 0x77, 0xb4);
#[cfg(feature = "svg")]
const BARS: RGBColor = RGBColor(0xd6, 0x27, 0x28);

/// A tick label for `v` on an axis whose ticks are multiples of `step` (1, 2 or 5 times a
/// power of ten): as many digits as tell neighbouring ticks apart (a mean that barely moves
/// needs many), no more.
fn tick(v: f64, step: f64) -> String {
    if v == 0.0 || !step.is_finite() || step <= 0.0 {
        return "0".into();
    }
    let magnitude = v.abs().log10().floor();
    let resolution = step.log10().floor();
    if (-2.0..4.0).contains(&magnitude) {
        let decimals = (-resolution).clamp(0.0, 15.0) as usize;
        format!("{v:.decimals$}")
    } else {
        let digits = (magnitude - resolution).clamp(1.0, 15.0) as usize;
        format!("{v:.digits$e}")
    }
}

/// The spacing plotters gives at most `max` ticks on a range of width `width`: the smallest of
/// 1, 2 and 5 times a power of ten that fits them (the search of plotters' `key_points`, one
/// candidate finer so that a label never has too few digits).
fn tick_step(width: f64, max: usize) -> f64 {
    let mut step = 10f64.powf((width / max as f64).log10().floor());
    for factor in [2.0, 2.5, 2.0].iter().cycle().take(12) {
        if width / step < (max + 1) as f64 {
            break;
        }
        step *= factor;
    }
    step
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
    let pad = if hi - lo <= 1e-12 * hi.abs().max(lo.abs()).max(1e-300) {
        if lo == 0.0 { 1.0 } else { 1e-6 * lo.abs() }
    } else {
        padding * (hi - lo)
    };
    // Values near f64::MAX have no finite width to draw (plotters' tick search would not end).
    let (lo, hi) = (lo - pad, hi + pad);
    (lo.is_finite() && hi.is_finite() && (hi - lo).is_finite()).then_some((lo, hi))
}

/// The power of ten that brings values as large as `lo` and `hi` to order one, if they are
/// tiny: plotters finds no ticks on a range narrower than f64::EPSILON (a cross section of
/// 1e-18 cm²), so such values are drawn scaled, with the scale in the axis label.
fn y_scale(lo: f64, hi: f64) -> (f64, Option<i32>) {
    let largest = lo.abs().max(hi.abs());
    // Below 1e-300 the scale itself would overflow: such values are drawn as they are.
    if !(1e-300..1e-6).contains(&largest) {
        return (1.0, None);
    }
    let exponent = largest.log10().floor() as i32;
    (10f64.powi(-exponent), Some(exponent))
}

/// Draws `p` into `area`; `None` if plotters reports an error (the panel is then left unfinished).
#[cfg(feature = "svg")]
fn panel(area: &DrawingArea<SVGBackend<'_>, Shift>, p: &Panel) -> Option<()> {
    let (xs, ys): (Vec<f64>, Vec<f64>) = match &p.content {
        Content::Band(v) => {
            (v.iter().map(|a| a.0).collect(), v.iter().flat_map(|a| [a.1 - a.2, a.1 + a.2, a.1]).collect())
        }
        Content::Bars(v) => (v.iter().flat_map(|a| [a.0, a.1]).collect(), v.iter().map(|a| a.2).chain([0.0]).collect()),
    };
    let (Some((xlo, xhi)), Some((ylo, yhi))) = (range(xs.into_iter(), 0.0), range(ys.into_iter(), 0.05)) else {
        area.titled(&p.title, ("sans-serif", 13)).ok()?;
        return area.draw_text("no data", &("sans-serif", 12).into(), (90, H as i32 / 2)).ok();
    };
    // Bars stand on zero.
    let ylo = if matches!(p.content, Content::Bars(_)) { 0.0 } else { ylo };
    let (scale, exponent) = y_scale(ylo, yhi);
    let y_label = match exponent {
        Some(e) => format!("{} [×1e{e}]", p.y_label),
        None => p.y_label.clone(),
    };
    let mut chart = ChartBuilder::on(area)
        .caption(&p.title, ("sans-serif", 13))
        .margin(8)
        .margin_right(22)
        .x_label_area_size(38)
        .y_label_area_size(72)
        .build_cartesian_2d(xlo..xhi, ylo * scale..yhi * scale)
        .ok()?;
    let (xstep, ystep) = (tick_step(xhi - xlo, 5), tick_step(scale * (yhi - ylo), 5));
    chart
        .configure_mesh()
        .disable_mesh()
        .x_labels(5)
        .y_labels(5)
        .x_label_formatter(&|x| tick(*x, xstep))
        .y_label_formatter(&|y| tick(*y, ystep))
        .x_desc(&p.x_label)
        .y_desc(&y_label)
        .draw()
        .ok()?;
    match &p.content {
        Content::Band(v) => {
            let finite: Vec<&(f64, f64, f64)> = v.iter().filter(|a| a.0.is_finite() && a.1.is_finite()).collect();
            if !finite.is_empty() && finite.iter().all(|a| a.2.is_finite()) {
                let upper = finite.iter().map(|a| (a.0, scale * (a.1 + a.2.abs())));
                let lower = finite.iter().rev().map(|a| (a.0, scale * (a.1 - a.2.abs())));
                chart
                    .draw_series([Polygon::new(upper.chain(lower).collect::<Vec<_>>(), BAND.mix(0.25).filled())])
                    .ok()?;
            }
            chart.draw_series(LineSeries::new(finite.iter().map(|a| (a.0, scale * a.1)), BAND.stroke_width(2))).ok()?;
        }
        Content::Bars(v) => {
            let bars = v.iter().filter(|b| b.2.is_finite() && b.2 > 0.0);
            chart
                .draw_series(
                    bars.map(|&(lo, hi, h)| Rectangle::new([(lo, 0.0), (hi, scale * h)], BARS.mix(0.7).filled())),
                )
                .ok()?;
        }
    }
    Some(())
}

/// The panels in a grid of up to three columns, as a standalone SVG document.
#[cfg(feature = "svg")]
pub fn svg(panels: &[Panel]) -> String {
    let columns = panels.len().clamp(1, COLUMNS);
    let rows = panels.len().div_ceil(COLUMNS).max(1);
    let mut out = String::new();
    {
        let root = SVGBackend::with_string(&mut out, (W * columns as u32, H * rows as u32)).into_drawing_area();
        // Drawing into a string cannot fail for lack of room; a panel that fails is left blank.
        let _ = root.fill(&WHITE);
        if panels.is_empty() {
            let text = "nothing to plot: the scene's [statistics] asks for none";
            let _ = root.draw_text(text, &("sans-serif", 13).into(), (20, 40));
        }
        for (area, p) in root.split_evenly((rows, columns)).iter().zip(panels) {
            let _ = panel(area, p);
        }
        let _ = root.present();
    }
    out
}

#[cfg(all(test, feature = "svg"))]
mod tests {
    use super::*;

    #[test]
    fn ticks_have_the_digits_that_tell_them_apart() {
        assert_eq!(tick(8.77512, 1e-5), "8.77512");
        assert_eq!(tick(2500.0, 500.0), "2500");
        assert_eq!(tick(4.5691e-3, 1e-9), "4.569100e-3");
        assert_eq!(tick(0.0, 1.0), "0");
        assert_eq!(tick(-1.5, 0.5), "-1.5");
        assert_eq!(tick(1.84, 0.02), "1.84");
    }

    #[test]
    fn tick_steps_are_one_two_or_five_times_a_power_of_ten_with_at_most_six_ticks() {
        for (width, step) in [(2.9, 0.5), (0.05, 0.01), (0.035, 0.01), (4900.0, 1000.0), (1e-9, 2e-10)] {
            let got = tick_step(width, 5);
            assert!((got / step - 1.0).abs() < 1e-12, "width {width}: step {got}, expected {step}");
            assert!(width / got < 6.0);
        }
    }

    /// The text of every `<text>` element of an SVG document.
    fn texts(svg: &str) -> Vec<String> {
        let body = |t: &str| -> Option<String> {
            let t = &t[t.find('>')? + 1..];
            Some(t[..t.find("</text>")?].trim().to_owned())
        };
        svg.split("<text").skip(1).filter_map(body).collect()
    }

    fn band_panel(title: &str, scale: f64) -> Panel {
        let band = (0..50).map(|i| (f64::from(i) * 100.0, scale * (f64::from(i) / 10.0).sin().abs(), 0.0)).collect();
        Panel { title: title.into(), x_label: "x".into(), y_label: "σ (cm²)".into(), content: Content::Band(band) }
    }

    #[test]
    fn a_cross_section_of_1e_18_cm2_gets_y_ticks_and_its_scale() {
        let t = texts(&svg(&[band_panel("spectrum", 1.3e-18)]));
        assert!(t.iter().any(|s| s == "σ (cm²) [×1e-18]"), "no scaled axis label in {t:?}");
        // Five x ticks and at least three y ticks (plotters alone gives one y tick here).
        let numbers = t.iter().filter(|s| s.parse::<f64>().is_ok()).count();
        assert!(numbers >= 8, "{numbers} tick labels in {t:?}");
        let t = texts(&svg(&[band_panel("spectrum", 1.3)]));
        assert!(t.iter().any(|s| s == "σ (cm²)"), "an order-one axis is not scaled: {t:?}");
    }

    #[test]
    fn titles_are_escaped() {
        let s = svg(&[band_panel("a < b & c", 1.0)]);
        assert!(s.contains("a &lt; b &amp; c") && !s.contains("a < b"), "{s}");
    }

    /// Values no ensemble should produce, but might: drawn or reported as "no data", without a
    /// panic (plotters asserts on NaN ranges) or a hang (its tick search on an infinite width).
    #[test]
    fn extreme_values_draw_without_panic_or_hang() {
        for values in [[1e-320, 2e-320], [-1.7e308, 1.7e308], [f64::MAX, f64::MAX], [0.0, 5e-324], [f64::NAN, 1.0]] {
            let band = values.iter().enumerate().map(|(i, &v)| (i as f64, v, 0.0)).collect();
            let bars = values.iter().enumerate().map(|(i, &v)| (i as f64, i as f64 + 1.0, v)).collect();
            let panels = [
                Panel { title: "band".into(), x_label: "x".into(), y_label: "y".into(), content: Content::Band(band) },
                Panel { title: "bars".into(), x_label: "x".into(), y_label: "y".into(), content: Content::Bars(bars) },
            ];
            assert!(svg(&panels).contains("</svg>"), "{values:?}");
        }
    }
}
