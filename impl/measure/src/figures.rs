//! Figures with `plotters`: line charts written as SVG and PNG, text laid out with the DejaVu Sans font embedded in
//! the binary (`ab_glyph`), so nothing links fontconfig or freetype and a fresh machine needs no fonts installed.
//!
//! A logarithmic axis is drawn as log10 of the values on a linear axis, labelled with the values themselves. Every
//! chart carries footer lines (command, commit, machine, seeds, transport) under the plot, so a figure separated
//! from its report still says how it was obtained.

use std::path::Path;
use std::sync::Once;

use anyhow::anyhow;
use plotters::coord::Shift;
use plotters::prelude::*;

/// Name under which the embedded font is registered.
const FONT: &str = "sans-serif";
/// Pixel size of every figure.
pub const SIZE: (u32, u32) = (900, 560);

/// One line (with markers) on a chart.
#[derive(Clone, Debug, Default)]
pub struct Series {
    /// Legend text.
    pub name: String,
    /// Points `(x, y)` in the values' own units (not logarithms).
    pub points: Vec<(f64, f64)>,
}

/// A line chart.
#[derive(Clone, Debug, Default)]
pub struct Chart {
    /// Title above the plot.
    pub title: String,
    /// Horizontal axis label.
    pub x_label: String,
    /// Vertical axis label.
    pub y_label: String,
    /// Logarithmic horizontal axis (values must be positive; others are left out).
    pub x_log: bool,
    /// Logarithmic vertical axis.
    pub y_log: bool,
    /// The lines.
    pub series: Vec<Series>,
    /// Lines of small text under the plot: how the figure was obtained.
    pub footer: Vec<String>,
    /// Legend in the upper left corner instead of the lower right.
    pub legend_upper_left: bool,
}

fn register_font() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        // The embedded font is valid TrueType; if registration failed, text would be missing, not wrong.
        let _ = plotters::style::register_font(FONT, FontStyle::Normal, dejavu::sans::regular());
    });
}

/// A number in few characters: 1.5k, 2M, 0.25.
pub fn short_number(v: f64) -> String {
    let a = v.abs();
    if a >= 1e9 {
        format!("{}G", trim(v / 1e9))
    } else if a >= 1e6 {
        format!("{}M", trim(v / 1e6))
    } else if a >= 1e3 {
        format!("{}k", trim(v / 1e3))
    } else {
        trim(v)
    }
}

fn trim(v: f64) -> String {
    let text = format!("{v:.2}");
    text.trim_end_matches('0').trim_end_matches('.').to_owned()
}

fn axis(values: impl Iterator<Item = f64>, log: bool) -> (f64, f64) {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for v in values {
        let v = if log { v.log10() } else { v };
        lo = lo.min(v);
        hi = hi.max(v);
    }
    if !lo.is_finite() || !hi.is_finite() {
        return (0.0, 1.0);
    }
    if !log {
        lo = lo.min(0.0);
    }
    if hi - lo < 1e-9 {
        hi = lo + 1.0;
    }
    let pad = (hi - lo) * 0.05;
    (if log { lo - pad } else { lo }, hi + pad)
}

const COLOURS: [RGBColor; 8] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(127, 127, 127),
];

fn draw<DB: DrawingBackend>(root: &DrawingArea<DB, Shift>, chart: &Chart) -> anyhow::Result<()>
where
    DB::ErrorType: 'static,
{
    let error = |e: DrawingAreaErrorKind<DB::ErrorType>| anyhow!("drawing {}: {e:?}", chart.title);
    root.fill(&WHITE).map_err(error)?;
    let footer_height = 16 * chart.footer.len() as u32 + 8;
    let (plot, footer) = root.split_vertically(SIZE.1 - footer_height);
    for (i, line) in chart.footer.iter().enumerate() {
        footer
            .draw_text(line, &(FONT, 12).into_font().color(&RGBColor(80, 80, 80)), (10, 4 + 16 * i as i32))
            .map_err(error)?;
    }
    let usable = |(x, y): &(f64, f64)| (!chart.x_log || *x > 0.0) && (!chart.y_log || *y > 0.0);
    let all = || chart.series.iter().flat_map(|s| s.points.iter().filter(|p| usable(p)));
    let (x0, x1) = axis(all().map(|p| p.0), chart.x_log);
    let (y0, y1) = axis(all().map(|p| p.1), chart.y_log);
    let mut ctx = ChartBuilder::on(&plot)
        .caption(&chart.title, (FONT, 20))
        .margin(12)
        .x_label_area_size(44)
        .y_label_area_size(70)
        .build_cartesian_2d(x0..x1, y0..y1)
        .map_err(error)?;
    let (x_log, y_log) = (chart.x_log, chart.y_log);
    let x_fmt = move |v: &f64| short_number(if x_log { 10f64.powf(*v) } else { *v });
    let y_fmt = move |v: &f64| short_number(if y_log { 10f64.powf(*v) } else { *v });
    ctx.configure_mesh()
        .x_desc(&chart.x_label)
        .y_desc(&chart.y_label)
        .x_label_formatter(&x_fmt)
        .y_label_formatter(&y_fmt)
        .label_style((FONT, 13))
        .axis_desc_style((FONT, 14))
        .light_line_style(RGBColor(235, 235, 235))
        .draw()
        .map_err(error)?;
    let map = |(x, y): &(f64, f64)| (if x_log { x.log10() } else { *x }, if y_log { y.log10() } else { *y });
    for (i, series) in chart.series.iter().enumerate() {
        let colour = COLOURS[i % COLOURS.len()];
        let points: Vec<(f64, f64)> = series.points.iter().filter(|p| usable(p)).map(map).collect();
        ctx.draw_series(LineSeries::new(points.iter().copied(), colour.stroke_width(2)))
            .map_err(error)?
            .label(&series.name)
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], colour.stroke_width(2)));
        if points.len() <= 40 {
            ctx.draw_series(points.iter().map(|&p| Circle::new(p, 3, colour.filled()))).map_err(error)?;
        }
    }
    if chart.series.len() > 1 || chart.series.first().is_some_and(|s| !s.name.is_empty()) {
        ctx.configure_series_labels()
            .position(if chart.legend_upper_left {
                SeriesLabelPosition::UpperLeft
            } else {
                SeriesLabelPosition::LowerRight
            })
            .label_font((FONT, 13))
            .background_style(WHITE.mix(0.85))
            .border_style(RGBColor(180, 180, 180))
            .draw()
            .map_err(error)?;
    }
    root.present().map_err(error)?;
    Ok(())
}

/// Writes `chart` as `dir/stem.svg` and `dir/stem.png`.
///
/// # Errors
/// A file that cannot be written, or a drawing error.
pub fn render(chart: &Chart, dir: &Path, stem: &str) -> anyhow::Result<()> {
    register_font();
    let svg = dir.join(format!("{stem}.svg"));
    draw(&SVGBackend::new(&svg, SIZE).into_drawing_area(), chart)?;
    let png = dir.join(format!("{stem}.png"));
    draw(&BitMapBackend::new(&png, SIZE).into_drawing_area(), chart)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn short_numbers() {
        assert_eq!(short_number(1_500.0), "1.5k");
        assert_eq!(short_number(2_000_000.0), "2M");
        assert_eq!(short_number(0.25), "0.25");
        assert_eq!(short_number(12.0), "12");
    }

    #[test]
    fn writes_an_svg_with_the_text_and_a_png() {
        let dir = std::env::temp_dir().join(format!("measure-figures-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let chart = Chart {
            title: "latency".into(),
            x_label: "ms".into(),
            y_label: "fraction".into(),
            x_log: true,
            series: vec![Series { name: "N=2".into(), points: vec![(0.1, 0.0), (1.0, 0.5), (10.0, 1.0)] }],
            footer: vec!["command: cortex report --quick".into()],
            ..Chart::default()
        };
        render(&chart, &dir, "cdf").unwrap();
        let svg = std::fs::read_to_string(dir.join("cdf.svg")).unwrap();
        assert!(svg.contains("latency") && svg.contains("command: cortex report --quick") && svg.contains("N=2"));
        let png = std::fs::read(dir.join("cdf.png")).unwrap();
        assert_eq!(&png[1..4], b"PNG");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
