//! Lane figures: one horizontal lane per subject (an agent), coloured by what it showed over time, behind which
//! labelled bands mark intervals (faults). `cortex chaos` draws its timeline this way. Written as SVG and PNG with
//! the same embedded font and footer as [`crate::figures`].

use std::path::Path;

use anyhow::anyhow;
use plotters::coord::Shift;
use plotters::prelude::*;

use crate::figures::{FONT, SIZE, draw_footer, footer_height, register_font};

/// A state a lane can show, with its legend text and colour.
#[derive(Clone, Debug)]
pub struct LaneState {
    /// Legend text.
    pub name: String,
    /// Colour, `(r, g, b)`.
    pub rgb: (u8, u8, u8),
}

/// One lane: stretches `(from, to, state index)` in the x axis's units.
#[derive(Clone, Debug, Default)]
pub struct Lane {
    /// Label at the left.
    pub name: String,
    /// The stretches.
    pub segments: Vec<(f64, f64, usize)>,
}

/// A labelled interval behind every lane.
#[derive(Clone, Debug)]
pub struct Band {
    /// Start.
    pub from: f64,
    /// End.
    pub to: f64,
    /// Label, drawn at the band's top.
    pub label: String,
}

/// A lane figure.
#[derive(Clone, Debug, Default)]
pub struct Lanes {
    /// Title above the plot.
    pub title: String,
    /// Horizontal axis label.
    pub x_label: String,
    /// Horizontal range.
    pub x_range: (f64, f64),
    /// The states lanes show.
    pub states: Vec<LaneState>,
    /// The lanes, top to bottom.
    pub lanes: Vec<Lane>,
    /// The bands.
    pub bands: Vec<Band>,
    /// Small text under the plot: how the figure was obtained.
    pub footer: Vec<String>,
}

/// Writes `lanes` as `dir/stem.svg` and `dir/stem.png`.
///
/// # Errors
/// A file that cannot be written, or a drawing error.
pub fn render(lanes: &Lanes, dir: &Path, stem: &str) -> anyhow::Result<()> {
    register_font();
    let height = 160 + 36 * (lanes.lanes.len() + lanes.states.len()) as u32 + footer_height(&lanes.footer);
    let size = (SIZE.0 + 300, height);
    let svg = dir.join(format!("{stem}.svg"));
    draw(&SVGBackend::new(&svg, size).into_drawing_area(), lanes)?;
    let png = dir.join(format!("{stem}.png"));
    draw(&BitMapBackend::new(&png, size).into_drawing_area(), lanes)?;
    Ok(())
}

fn draw<DB: DrawingBackend>(root: &DrawingArea<DB, Shift>, lanes: &Lanes) -> anyhow::Result<()>
where
    DB::ErrorType: 'static,
{
    let error = |e: DrawingAreaErrorKind<DB::ErrorType>| anyhow!("drawing {}: {e:?}", lanes.title);
    root.fill(&WHITE).map_err(error)?;
    let plot = draw_footer(root, &lanes.footer).map_err(error)?;
    let rows = lanes.lanes.len().max(1) as f64;
    // Room under the lanes for the legend.
    let legend_rows = 0.45 * lanes.states.len() as f64;
    let (x0, x1) = lanes.x_range;
    let mut ctx = ChartBuilder::on(&plot)
        .caption(&lanes.title, (FONT, 20))
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(60)
        .build_cartesian_2d(x0..x1.max(x0 + 1.0), -legend_rows..rows + 0.6)
        .map_err(error)?;
    let names: Vec<String> = lanes.lanes.iter().map(|l| l.name.clone()).collect();
    let y_fmt = move |v: &f64| {
        let row = rows - v.round();
        if (v - v.round()).abs() < 1e-6 && row >= 0.0 && (row as usize) < names.len() {
            names[row as usize].clone()
        } else {
            String::new()
        }
    };
    ctx.configure_mesh()
        .x_desc(&lanes.x_label)
        .y_labels(lanes.lanes.len() * 2 + 2)
        .y_label_formatter(&y_fmt)
        .disable_y_mesh()
        .label_style((FONT, 13))
        .axis_desc_style((FONT, 14))
        .light_line_style(RGBColor(235, 235, 235))
        .draw()
        .map_err(error)?;
    for (i, band) in lanes.bands.iter().enumerate() {
        let shade = if i % 2 == 0 { RGBColor(255, 200, 150) } else { RGBColor(200, 200, 255) };
        ctx.draw_series(std::iter::once(Rectangle::new(
            [(band.from, 0.4), (band.to, rows + 0.6)],
            shade.mix(0.35).filled(),
        )))
        .map_err(error)?;
        let style = (FONT, 11).into_font().color(&RGBColor(90, 60, 30));
        ctx.draw_series(std::iter::once(Text::new(band.label.clone(), (band.from, rows + 0.55), style)))
            .map_err(error)?;
    }
    for (row, lane) in lanes.lanes.iter().enumerate() {
        let y = rows - row as f64;
        for &(from, to, state) in &lane.segments {
            let Some(state) = lanes.states.get(state) else { continue };
            let colour = RGBColor(state.rgb.0, state.rgb.1, state.rgb.2);
            ctx.draw_series(std::iter::once(Rectangle::new([(from, y - 0.3), (to, y + 0.3)], colour.filled())))
                .map_err(error)?;
        }
    }
    for state in &lanes.states {
        let colour = RGBColor(state.rgb.0, state.rgb.1, state.rgb.2);
        ctx.draw_series(std::iter::empty::<Rectangle<(f64, f64)>>())
            .map_err(error)?
            .label(&state.name)
            .legend(move |(x, y)| Rectangle::new([(x, y - 5), (x + 18, y + 5)], colour.filled()));
    }
    ctx.configure_series_labels()
        .position(SeriesLabelPosition::LowerRight)
        .label_font((FONT, 13))
        .background_style(WHITE.mix(0.85))
        .border_style(RGBColor(180, 180, 180))
        .draw()
        .map_err(error)?;
    root.present().map_err(error)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn writes_lanes_bands_and_legend() {
        let dir = std::env::temp_dir().join(format!("measure-lanes-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let lanes = Lanes {
            title: "chaos".into(),
            x_label: "s".into(),
            x_range: (0.0, 10.0),
            states: vec![
                LaneState { name: "agrees".into(), rgb: (60, 170, 90) },
                LaneState { name: "differs".into(), rgb: (220, 60, 60) },
            ],
            lanes: vec![Lane { name: "a0".into(), segments: vec![(0.0, 4.0, 0), (4.0, 10.0, 1)] }],
            bands: vec![Band { from: 2.0, to: 5.0, label: "partition".into() }],
            footer: vec!["command: cortex chaos --seed 1".into()],
        };
        render(&lanes, &dir, "lanes").unwrap();
        let svg = std::fs::read_to_string(dir.join("lanes.svg")).unwrap();
        for text in ["partition", "agrees", "differs", "a0", "cortex chaos --seed 1"] {
            assert!(svg.contains(text), "{text} missing");
        }
        assert_eq!(&std::fs::read(dir.join("lanes.png")).unwrap()[1..4], b"PNG");
        let _ = std::fs::remove_dir_all(&dir);
    }
}
