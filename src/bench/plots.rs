//! The plots of a bench run (SVG through plotters).

use std::path::Path;

use anyhow::Result;

use super::{BenchRun, FrameRecord};

/// Tableau 10, reference in black: distinct at a glance.
const PALETTE: [plotters::style::RGBColor; 10] = [
    plotters::style::RGBColor(0, 0, 0),
    plotters::style::RGBColor(31, 119, 180),
    plotters::style::RGBColor(255, 127, 14),
    plotters::style::RGBColor(44, 160, 44),
    plotters::style::RGBColor(214, 39, 40),
    plotters::style::RGBColor(148, 103, 189),
    plotters::style::RGBColor(140, 86, 75),
    plotters::style::RGBColor(227, 119, 194),
    plotters::style::RGBColor(127, 127, 127),
    plotters::style::RGBColor(23, 190, 207),
];

/// The references (shadowed or not) in black, the others in the order of `names`.
fn method_color(names: &[&String], name: &str) -> plotters::style::RGBColor {
    let is_reference = |n: &str| n == "reference" || n == super::SHADOWED_REFERENCE;
    if is_reference(name) {
        return PALETTE[0];
    }
    let i = names.iter().filter(|n| !is_reference(n)).position(|n| n.as_str() == name).unwrap_or(0);
    PALETTE[1 + i % (PALETTE.len() - 1)]
}

/// One line per method of `pick(frame)` along the path, with a legend.
fn per_method_lines<'a, DB, Y>(
    chart: &mut plotters::chart::ChartContext<
        'a,
        DB,
        plotters::coord::cartesian::Cartesian2d<plotters::coord::types::RangedCoordf64, Y>,
    >,
    run: &BenchRun,
    names: &[&String],
    pick: impl Fn(&FrameRecord) -> Option<f64>,
) -> Result<(), plotters::drawing::DrawingAreaErrorKind<DB::ErrorType>>
where
    DB: plotters::prelude::DrawingBackend + 'a,
    Y: plotters::coord::ranged1d::Ranged<ValueType = f64>,
{
    use plotters::prelude::*;
    for name in names {
        let c = method_color(names, name);
        let series: Vec<(f64, f64)> = run
            .frames
            .iter()
            .filter(|r| &&r.method == name)
            .filter_map(|r| pick(r).map(|v| (r.frame as f64, v)))
            .collect();
        chart
            .draw_series(LineSeries::new(series, c.stroke_width(2)))?
            .label(name.as_str())
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], c.stroke_width(2)));
    }
    chart.configure_series_labels().border_style(BLACK).background_style(WHITE.mix(0.85)).draw()
}

/// Writes the plots as SVG into `dir`: `pareto.svg` (median error vs median GPU
/// time per method), `frame_time.svg` (GPU ms along the path, like Clasen et al. 2010
/// Fig. 11) and `temporal_noise.svg` (like Fig. 13).
///
/// # Errors
/// Drawing or I/O errors.
pub fn write_plots(dir: &Path, run: &BenchRun, title: &str) -> Result<()> {
    use plotters::prelude::*;
    let names: Vec<&String> = run.summary.keys().collect();
    let color = |name: &str| method_color(&names, name);
    let plot_err = |e: Box<dyn std::error::Error>| anyhow::anyhow!("plotting: {e}");
    // Pareto: error against time.
    {
        let path = dir.join("pareto.svg");
        let root = SVGBackend::new(&path, (800, 520)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| plot_err(e.into()))?;
        let xs = run.summary.values().map(|m| m.gpu_ms.median).filter(|x| *x > 0.0);
        let xmin = xs.clone().fold(f64::MAX, f64::min).min(1e3) * 0.7;
        let xmax = xs.fold(1e-3, f64::max) * 1.5;
        let ymax = run.summary.values().map(|m| m.error.median).fold(1e-4, f64::max) * 1.2;
        let mut chart = ChartBuilder::on(&root)
            .caption(format!("Image error vs GPU time — {title}"), ("sans-serif", 18))
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(70)
            // log10 of the time on a linear axis, labelled in ms: plotters' own log
            // axis crowds its labels into the top decade.
            .build_cartesian_2d(xmin.max(1e-3).log10()..xmax.log10(), 0f64..ymax)
            .map_err(|e| plot_err(e.into()))?;
        chart
            .configure_mesh()
            .x_labels(8)
            .x_label_formatter(&|v| {
                let ms = 10f64.powf(*v);
                let digits = 10f64.powf(ms.log10().floor() - 1.0);
                format!("{}", (ms / digits).round() * digits)
            })
            .x_desc("median GPU ms per frame (log scale)")
            .y_desc("median multi-scale RMSE vs reference")
            .draw()
            .map_err(|e| plot_err(e.into()))?;
        // A legend, not labels by the points: the fast methods sit close together.
        for (name, m) in &run.summary {
            let c = color(name);
            let p = (m.gpu_ms.median.max(1e-3).log10(), m.error.median);
            chart
                .draw_series(std::iter::once(Circle::new(p, 6, c.filled())))
                .map_err(|e| plot_err(e.into()))?
                .label(name.as_str())
                .legend(move |(x, y)| Circle::new((x + 8, y), 5, c.filled()));
        }
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperMiddle)
            .border_style(BLACK)
            .background_style(WHITE.mix(0.85))
            .draw()
            .map_err(|e| plot_err(e.into()))?;
        root.present().map_err(|e| plot_err(e.into()))?;
    }
    let frames = run.frames.iter().map(|r| r.frame).max().unwrap_or(0) + 1;
    let x_range = 0f64..(frames as f64 - 1.0).max(1.0);
    // GPU time along the path, log scale (the methods span orders of magnitude).
    {
        let path = dir.join("frame_time.svg");
        let root = SVGBackend::new(&path, (900, 520)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| plot_err(e.into()))?;
        let vals: Vec<f64> = run.frames.iter().map(|r| r.gpu_ms).filter(|v| *v > 0.0).collect();
        let ymin = vals.iter().copied().fold(f64::MAX, f64::min).min(1e3) * 0.7;
        let ymax = vals.iter().copied().fold(1e-3, f64::max) * 1.5;
        let mut chart = ChartBuilder::on(&root)
            .caption(format!("GPU ms per frame along the path — {title}"), ("sans-serif", 16))
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(70)
            .build_cartesian_2d(x_range.clone(), (ymin.max(1e-3)..ymax).log_scale())
            .map_err(|e| plot_err(e.into()))?;
        chart
            .configure_mesh()
            .x_desc("frame along the path")
            .y_desc("GPU ms (log scale)")
            .draw()
            .map_err(|e| plot_err(e.into()))?;
        per_method_lines(&mut chart, run, &names, |r| Some(r.gpu_ms).filter(|v| *v > 0.0))
            .map_err(|e| plot_err(e.into()))?;
        root.present().map_err(|e| plot_err(e.into()))?;
    }
    // Temporal noise along the path.
    {
        let what = "temporal noise (RMSE to the previous frame minus the reference's)";
        let path = dir.join("temporal_noise.svg");
        let root = SVGBackend::new(&path, (900, 520)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| plot_err(e.into()))?;
        let vals: Vec<f64> = run.frames.iter().map(|r| r.temporal_noise).filter(|v| v.is_finite()).collect();
        let ymin = vals.iter().copied().fold(0.0, f64::min) * 1.1;
        let ymax = vals.iter().copied().fold(1e-6, f64::max) * 1.1;
        let mut chart = ChartBuilder::on(&root)
            .caption(format!("{what} — {title}"), ("sans-serif", 16))
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(70)
            .build_cartesian_2d(x_range, ymin..ymax)
            .map_err(|e| plot_err(e.into()))?;
        chart.configure_mesh().x_desc("frame along the path").y_desc(what).draw().map_err(|e| plot_err(e.into()))?;
        per_method_lines(&mut chart, run, &names, |r| Some(r.temporal_noise).filter(|v| v.is_finite()))
            .map_err(|e| plot_err(e.into()))?;
        root.present().map_err(|e| plot_err(e.into()))?;
    }
    Ok(())
}
