//! Figures of benchmark results (SVG, with plotters).

use anyhow::{Context, Result};
use plotters::prelude::*;
use std::path::Path;

/// Colors of the curves, in order (red marks real time).
const CURVE_COLORS: [RGBColor; 4] = [
    RGBColor(31, 90, 200),
    RGBColor(0, 140, 60),
    RGBColor(170, 40, 170),
    RGBColor(200, 120, 0),
];

/// One curve of a scaling figure: its label, and for each team size the
/// real-time factors of the runs repeated at that size.
pub struct Curve {
    /// What the curve shows (e.g. "one thread").
    pub label: String,
    /// Team size, and the factor of every run at that size.
    pub points: Vec<(usize, Vec<f64>)>,
}

/// The scaling figure of `bite bench sim` and `bite bench team`: simulated
/// seconds per wall second against team size, both on log scales, with
/// real time marked; one curve per thread count through the median of the
/// repeated runs, with a bar from the slowest to the fastest run (the
/// run-to-run spread).
pub fn scaling(path: &Path, title: &str, curves: &[Curve]) -> Result<()> {
    let root = SVGBackend::new(path, (720, 440)).into_drawing_area();
    let all = || curves.iter().flat_map(|c| &c.points);
    let values = || all().flat_map(|(_, v)| v.iter().copied());
    let draw = || -> Result<(), Box<dyn std::error::Error>> {
        root.fill(&WHITE)?;
        let xmax = all().map(|p| p.0).max().unwrap_or(10).max(10) as f64 * 2.0;
        let xmin = (all().map(|p| p.0).min().unwrap_or(10) as f64 / 2.0).clamp(1.0, 5.0);
        let ymax = values().fold(10.0, f64::max) * 3.0;
        let ymin = values().fold(1.0, f64::min) / 3.0;
        let mut chart = ChartBuilder::on(&root)
            .caption(title, ("sans-serif", 18))
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(60)
            .build_cartesian_2d((xmin..xmax).log_scale(), (ymin..ymax).log_scale())?;
        chart
            .configure_mesh()
            .x_desc("robots")
            .y_desc("simulated s per wall s")
            .x_label_formatter(&|x| format!("{x:.0}"))
            .y_label_formatter(&|y| format!("{y}×"))
            .draw()?;
        chart
            .draw_series(LineSeries::new(
                [(xmin, 1.0), (xmax, 1.0)],
                ShapeStyle::from(&RED).stroke_width(1),
            ))?
            .label("real time")
            .legend(|(x, y)| PathElement::new([(x, y), (x + 20, y)], RED));
        for (k, c) in curves.iter().enumerate() {
            let color = CURVE_COLORS[k % CURVE_COLORS.len()];
            let spread: Vec<(f64, f64, f64, f64)> = c
                .points
                .iter()
                .filter(|(_, v)| !v.is_empty())
                .map(|(n, v)| {
                    let mut v = v.clone();
                    v.sort_by(f64::total_cmp);
                    let lo = v[0];
                    let hi = v[v.len() - 1];
                    (*n as f64, crate::stats::quantile(&v, 0.5), lo, hi)
                })
                .collect();
            let mid: Vec<(f64, f64)> = spread.iter().map(|p| (p.0, p.1)).collect();
            chart
                .draw_series(LineSeries::new(mid.clone(), color.stroke_width(2)))?
                .label(c.label.clone())
                .legend(move |(x, y)| PathElement::new([(x, y), (x + 20, y)], color));
            chart.draw_series(mid.iter().map(|p| Circle::new(*p, 4, color.filled())))?;
            chart.draw_series(
                spread
                    .iter()
                    .map(|(x, m, lo, hi)| ErrorBar::new_vertical(*x, *lo, *m, *hi, color, 8)),
            )?;
            chart.draw_series(mid.iter().map(|(x, y)| {
                Text::new(
                    if *y < 1.0 {
                        format!("{y:.2}×")
                    } else {
                        format!("{y:.1}×")
                    },
                    (*x * 1.1, *y * (1.25 + 0.35 * k as f64)),
                    ("sans-serif", 13),
                )
            }))?;
        }
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

/// Draw a picture into an SVG string with plotters, then write it as
/// `<dir>/<name>.svg` and `<dir>/<name>.png`; returns `name`.
fn svg_and_png(
    dir: &Path,
    name: &str,
    size: (u32, u32),
    draw: impl FnOnce(
        &DrawingArea<SVGBackend<'_>, plotters::coord::Shift>,
    ) -> Result<(), Box<dyn std::error::Error>>,
) -> Result<String> {
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, size).into_drawing_area();
        draw(&root).map_err(|e| anyhow::anyhow!("{e}"))?;
        root.present().map_err(|e| anyhow::anyhow!("{e}"))?;
    }
    let svg_path = dir.join(format!("{name}.svg"));
    std::fs::write(&svg_path, &svg).with_context(|| format!("writing {}", svg_path.display()))?;
    let png_path = dir.join(format!("{name}.png"));
    let png = crate::anim::rasterise(&svg, size.0, &crate::anim::svg_options())
        .and_then(|p| p.encode_png().map_err(|e| anyhow::anyhow!("{e}")))
        .with_context(|| format!("drawing {}", png_path.display()))?;
    std::fs::write(&png_path, png).with_context(|| format!("writing {}", png_path.display()))?;
    Ok(name.to_string())
}

fn upper(values: impl IntoIterator<Item = f64>) -> f64 {
    let m = values
        .into_iter()
        .filter(|x| x.is_finite())
        .fold(0.0, f64::max);
    if m > 0.0 { m * 1.15 } else { 1.0 }
}

/// A chart in the style of the BITE paper's Figure 3 for one group of an
/// experiment: per configuration, the mean interaction time by kind (left
/// axis) and the mean task time (right axis), each with its 95 %
/// confidence interval, and the median task time.
pub fn figure3(dir: &Path, g: &crate::experiment::Group) -> Result<String> {
    let k = g.configs.len();
    let kinds = [
        (
            "interaction_time.sync",
            "synchronization",
            RGBColor(31, 119, 180),
        ),
        (
            "interaction_time.allocate",
            "allocation",
            RGBColor(44, 160, 44),
        ),
        (
            "interaction_time.total",
            "interaction (all)",
            RGBColor(148, 103, 189),
        ),
    ];
    let inter: Vec<Vec<crate::stats::Describe>> = kinds
        .iter()
        .map(|(f, _, _)| (0..k).map(|i| g.describe(i, f)).collect())
        .collect();
    let task: Vec<crate::stats::Describe> = (0..k).map(|i| g.describe(i, "task_time")).collect();
    // Head room above the data for the legend.
    let y1 = upper(inter.iter().flatten().map(|d| d.mean + d.ci95)) * 1.5;
    let y2 = upper(task.iter().map(|d| (d.mean + d.ci95).max(d.median))) * 1.5;
    let labels = g.configs.clone();
    let title = format!("{}: time per configuration (mean, 95 % CI)", g.title);
    svg_and_png(dir, &format!("figure3-{}", g.slug), (900, 560), |root| {
        root.fill(&WHITE)?;
        let xr = -0.5..(k as f64 - 0.5);
        let mut chart = ChartBuilder::on(root)
            .caption(&title, ("sans-serif", 18))
            .margin(14)
            .x_label_area_size(40)
            .y_label_area_size(60)
            .right_y_label_area_size(60)
            .build_cartesian_2d(xr.clone(), 0.0..y1)?
            .set_secondary_coord(xr, 0.0..y2);
        let fmt = |x: &f64| {
            let i = x.round();
            if (x - i).abs() < 1e-6 && i >= 0.0 && (i as usize) < labels.len() {
                labels[i as usize].clone()
            } else {
                String::new()
            }
        };
        chart
            .configure_mesh()
            .x_labels(k.max(2) * 2 + 1)
            .x_label_formatter(&fmt)
            .x_desc("configuration")
            .y_desc("interaction time per robot (s)")
            .disable_x_mesh()
            .draw()?;
        chart
            .configure_secondary_axes()
            .y_desc("task time (s)")
            .draw()?;
        for (j, ((_, name, colour), ds)) in kinds.iter().zip(&inter).enumerate() {
            let dx = (j as f64 - 1.0) * 0.08;
            let pts: Vec<(f64, f64)> = ds
                .iter()
                .enumerate()
                .filter(|(_, d)| d.mean.is_finite())
                .map(|(i, d)| (i as f64 + dx, d.mean))
                .collect();
            chart
                .draw_series(LineSeries::new(pts.clone(), colour.stroke_width(2)))?
                .label(*name)
                .legend(move |(x, y)| {
                    PathElement::new([(x, y), (x + 20, y)], colour.stroke_width(2))
                });
            chart.draw_series(
                ds.iter()
                    .enumerate()
                    .filter(|(_, d)| d.n > 0)
                    .map(|(i, d)| {
                        ErrorBar::new_vertical(
                            i as f64 + dx,
                            d.mean - d.ci95,
                            d.mean,
                            d.mean + d.ci95,
                            colour.filled(),
                            6,
                        )
                    }),
            )?;
        }
        let black = RGBColor(20, 20, 20);
        let pts: Vec<(f64, f64)> = task
            .iter()
            .enumerate()
            .filter(|(_, d)| d.mean.is_finite())
            .map(|(i, d)| (i as f64 + 0.2, d.mean))
            .collect();
        chart
            .draw_secondary_series(LineSeries::new(pts, black.stroke_width(3)))?
            .label("task time (right axis)")
            .legend(move |(x, y)| PathElement::new([(x, y), (x + 20, y)], black.stroke_width(3)));
        chart.draw_secondary_series(task.iter().enumerate().filter(|(_, d)| d.n > 0).map(
            |(i, d)| {
                ErrorBar::new_vertical(
                    i as f64 + 0.2,
                    d.mean - d.ci95,
                    d.mean,
                    d.mean + d.ci95,
                    black.filled(),
                    8,
                )
            },
        ))?;
        chart
            .draw_secondary_series(
                task.iter()
                    .enumerate()
                    .filter(|(_, d)| d.n > 0)
                    .map(|(i, d)| Cross::new((i as f64 + 0.2, d.median), 5, RED.stroke_width(2))),
            )?
            .label("median task time")
            .legend(|(x, y)| Cross::new((x + 10, y), 5, RED.stroke_width(2)));
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .position(SeriesLabelPosition::UpperRight)
            .draw()?;
        Ok(())
    })
}

/// Box plots of one figure per configuration of a group (quartiles, and
/// whiskers at 1.5 times the interquartile range).
pub fn boxes(dir: &Path, g: &crate::experiment::Group, figure: &str) -> Result<String> {
    let k = g.configs.len();
    let values: Vec<Vec<f64>> = (0..k).map(|i| g.values(i, figure)).collect();
    let top = upper(values.iter().flatten().copied()) as f32;
    let low = values
        .iter()
        .flatten()
        .copied()
        .filter(|x| x.is_finite())
        .fold(f64::INFINITY, f64::min);
    let bottom = if low.is_finite() && low > 0.0 {
        (low * 0.8) as f32
    } else {
        0.0
    };
    let labels = g.configs.clone();
    let title = format!("{}: {figure} per configuration", g.title);
    let name = format!(
        "box-{}-{}",
        g.slug,
        figure.replace(|c: char| !c.is_ascii_alphanumeric(), "-")
    );
    svg_and_png(dir, &name, (900, 480), |root| {
        root.fill(&WHITE)?;
        let mut chart = ChartBuilder::on(root)
            .caption(&title, ("sans-serif", 18))
            .margin(14)
            .x_label_area_size(40)
            .y_label_area_size(60)
            .build_cartesian_2d(labels[..].into_segmented(), bottom..top)?;
        chart
            .configure_mesh()
            .x_label_formatter(&|v| match v {
                SegmentValue::CenterOf(l) | SegmentValue::Exact(l) => (*l).clone(),
                SegmentValue::Last => String::new(),
            })
            .x_desc("configuration")
            .y_desc(figure)
            .disable_x_mesh()
            .draw()?;
        chart.draw_series(
            labels
                .iter()
                .zip(&values)
                .filter(|(_, v)| !v.is_empty())
                .map(|(l, v)| {
                    Boxplot::new_vertical(SegmentValue::CenterOf(l), &Quartiles::new(v))
                        .width(30)
                        .style(RGBColor(31, 119, 180))
                }),
        )?;
        Ok(())
    })
}
