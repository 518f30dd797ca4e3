//! Figures of benchmark results (SVG, with plotters).

use anyhow::{Context, Result};
use plotters::prelude::*;
use std::path::Path;

/// The scaling curve of `bite bench sim`: simulated seconds per wall second
/// against team size, both on log scales, with real time marked.
pub fn scaling(path: &Path, title: &str, points: &[(usize, f64)]) -> Result<()> {
    let root = SVGBackend::new(path, (720, 440)).into_drawing_area();
    let draw = || -> Result<(), Box<dyn std::error::Error>> {
        root.fill(&WHITE)?;
        let xmax = points.iter().map(|p| p.0).max().unwrap_or(10).max(10) as f64 * 2.0;
        let ymax = points.iter().map(|p| p.1).fold(10.0, f64::max) * 3.0;
        let ymin = points.iter().map(|p| p.1).fold(1.0, f64::min) / 3.0;
        let mut chart = ChartBuilder::on(&root)
            .caption(title, ("sans-serif", 20))
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(60)
            .build_cartesian_2d((5.0..xmax).log_scale(), (ymin..ymax).log_scale())?;
        chart
            .configure_mesh()
            .x_desc("robots")
            .y_desc("simulated s per wall s")
            .x_label_formatter(&|x| format!("{x:.0}"))
            .y_label_formatter(&|y| format!("{y}×"))
            .draw()?;
        chart
            .draw_series(LineSeries::new(
                [(5.0, 1.0), (xmax, 1.0)],
                ShapeStyle::from(&RED).stroke_width(1),
            ))?
            .label("real time")
            .legend(|(x, y)| PathElement::new([(x, y), (x + 20, y)], RED));
        let pts: Vec<(f64, f64)> = points.iter().map(|(n, f)| (*n as f64, *f)).collect();
        chart
            .draw_series(LineSeries::new(pts.clone(), BLUE.stroke_width(2)))?
            .label("coverage mission, one core")
            .legend(|(x, y)| PathElement::new([(x, y), (x + 20, y)], BLUE));
        chart.draw_series(pts.iter().map(|p| Circle::new(*p, 4, BLUE.filled())))?;
        chart.draw_series(pts.iter().map(|(x, y)| {
            Text::new(
                format!("{y:.1}×"),
                (*x * 1.1, *y * 1.25),
                ("sans-serif", 13),
            )
        }))?;
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .position(SeriesLabelPosition::UpperRight)
            .draw()?;
        root.present()?;
        Ok(())
    };
    draw()
        .map_err(|e| anyhow::anyhow!("{e}"))
        .with_context(|| format!("drawing {}", path.display()))
}
