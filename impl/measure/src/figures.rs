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
pub(crate) const FONT: &str = "sans-serif";
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

/// One panel of a figure of stacked panels ([`render_panels`]): a chart plus what only panels need.
#[derive(Clone, Debug, Default)]
pub struct Panel {
    /// The chart drawn in the panel (its `footer` is not drawn: the figure has one footer).
    pub chart: Chart,
    /// Series drawn as markers only (crosses, no line), for events such as deadline misses.
    pub markers: Vec<Series>,
    /// A fixed horizontal range `(min, max)`, so stacked panels share their axis.
    pub x_range: Option<(f64, f64)>,
    /// A shaded horizontal interval `(from, to, legend)`, such as an overload window.
    pub shaded: Option<(f64, f64, String)>,
}

/// Height in pixels of one panel of [`render_panels`].
pub const PANEL_HEIGHT: u32 = 300;

pub(crate) fn register_font() {
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

pub(crate) const COLOURS: [RGBColor; 8] = [
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
    let plot = draw_footer(root, &chart.footer).map_err(error)?;
    draw_plot(&plot, &Panel { chart: chart.clone(), ..Panel::default() })?;
    root.present().map_err(error)?;
    Ok(())
}

pub(crate) fn footer_height(lines: &[String]) -> u32 {
    16 * lines.len() as u32 + 8
}

/// Writes the footer lines at the bottom of `root` and returns the area above them.
pub(crate) fn draw_footer<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    lines: &[String],
) -> Result<DrawingArea<DB, Shift>, DrawingAreaErrorKind<DB::ErrorType>> {
    let (plot, footer) = root.split_vertically(root.dim_in_pixel().1 - footer_height(lines));
    for (i, line) in lines.iter().enumerate() {
        footer.draw_text(line, &(FONT, 12).into_font().color(&RGBColor(80, 80, 80)), (10, 4 + 16 * i as i32))?;
    }
    Ok(plot)
}

fn draw_plot<DB: DrawingBackend>(plot: &DrawingArea<DB, Shift>, panel: &Panel) -> anyhow::Result<()>
where
    DB::ErrorType: 'static,
{
    let chart = &panel.chart;
    let error = |e: DrawingAreaErrorKind<DB::ErrorType>| anyhow!("drawing {}: {e:?}", chart.title);
    let usable = |(x, y): &(f64, f64)| (!chart.x_log || *x > 0.0) && (!chart.y_log || *y > 0.0);
    let all = || chart.series.iter().chain(&panel.markers).flat_map(|s| s.points.iter().filter(|p| usable(p)));
    let (x0, x1) = match panel.x_range {
        Some((lo, hi)) if chart.x_log => (lo.log10(), hi.log10()),
        Some(range) => range,
        None => axis(all().map(|p| p.0), chart.x_log),
    };
    let (y0, y1) = axis(all().map(|p| p.1), chart.y_log);
    let mut ctx = ChartBuilder::on(plot)
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
    if let Some((from, to, name)) = &panel.shaded {
        let shade = RGBColor(255, 170, 170).mix(0.35).filled();
        let (from, to) = (map(&(*from, 1.0)).0, map(&(*to, 1.0)).0);
        ctx.draw_series(std::iter::once(Rectangle::new([(from, y0), (to, y1)], shade)))
            .map_err(error)?
            .label(name)
            .legend(move |(x, y)| Rectangle::new([(x, y - 5), (x + 18, y + 5)], shade));
    }
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
    for (i, series) in panel.markers.iter().enumerate() {
        // Red first: markers stand out from the first lines' blue, orange and green.
        let colour = COLOURS[(3 + i) % COLOURS.len()];
        let points: Vec<(f64, f64)> = series.points.iter().filter(|p| usable(p)).map(map).collect();
        ctx.draw_series(points.iter().map(|&p| Cross::new(p, 5, colour.stroke_width(2))))
            .map_err(error)?
            .label(&series.name)
            .legend(move |(x, y)| Cross::new((x + 9, y), 5, colour.stroke_width(2)));
    }
    let labelled = chart.series.len() > 1 || chart.series.first().is_some_and(|s| !s.name.is_empty());
    if labelled || !panel.markers.is_empty() || panel.shaded.is_some() {
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
    Ok(())
}

fn draw_panels<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    panels: &[Panel],
    footer: &[String],
) -> anyhow::Result<()>
where
    DB::ErrorType: 'static,
{
    let error = |e: DrawingAreaErrorKind<DB::ErrorType>| anyhow!("drawing a figure of {} panels: {e:?}", panels.len());
    root.fill(&WHITE).map_err(error)?;
    let plots = draw_footer(root, footer).map_err(error)?;
    for (area, panel) in plots.split_evenly((panels.len().max(1), 1)).iter().zip(panels) {
        draw_plot(area, panel)?;
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

/// Writes panels stacked vertically, [`PANEL_HEIGHT`] pixels each, with one footer under them, as `dir/stem.svg`
/// and `dir/stem.png`.
///
/// # Errors
/// A file that cannot be written, or a drawing error.
pub fn render_panels(panels: &[Panel], footer: &[String], dir: &Path, stem: &str) -> anyhow::Result<()> {
    register_font();
    let size = (SIZE.0, PANEL_HEIGHT * panels.len().max(1) as u32 + footer_height(footer));
    let svg = dir.join(format!("{stem}.svg"));
    draw_panels(&SVGBackend::new(&svg, size).into_drawing_area(), panels, footer)?;
    let png = dir.join(format!("{stem}.png"));
    draw_panels(&BitMapBackend::new(&png, size).into_drawing_area(), panels, footer)?;
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

    #[test]
    fn writes_stacked_panels_with_markers_and_a_shaded_interval() {
        let dir = std::env::temp_dir().join(format!("measure-panels-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let line = |title: &str| Chart {
            title: title.into(),
            series: vec![Series { name: "rate".into(), points: vec![(0.0, 20.0), (1.0, 9.0), (2.0, 20.0)] }],
            ..Chart::default()
        };
        let panels = [
            Panel { chart: line("upper panel"), x_range: Some((0.0, 3.0)), ..Panel::default() },
            Panel {
                chart: line("lower panel"),
                markers: vec![Series { name: "miss".into(), points: vec![(1.0, 9.0)] }],
                x_range: Some((0.0, 3.0)),
                shaded: Some((1.0, 2.0, "overload window".into())),
            },
        ];
        render_panels(&panels, &["commit abc".into()], &dir, "panels").unwrap();
        let svg = std::fs::read_to_string(dir.join("panels.svg")).unwrap();
        for text in ["upper panel", "lower panel", "miss", "overload window", "commit abc"] {
            assert!(svg.contains(text), "{text} missing from the svg");
        }
        assert!(svg.contains(&format!("height=\"{}\"", 2 * PANEL_HEIGHT + 24)), "two panels and one footer line");
        let png = std::fs::read(dir.join("panels.png")).unwrap();
        assert_eq!(&png[1..4], b"PNG");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
