//! Figures like the force-control paper's: Fig. 2 (identification reference and actual deformation), Figs. 3 and 4
//! (actual, predicted and commanded normal force over the control experiment), as SVG.

use std::path::{Path, PathBuf};

use plotters::prelude::*;

use super::experiment::{ModelUse, SurfaceRun};

type Result<T> = std::result::Result<T, Box<dyn std::error::Error>>;

fn range(values: impl Iterator<Item = f64>) -> std::ops::Range<f64> {
    let (lo, hi) = values.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| (lo.min(v), hi.max(v)));
    let pad = ((hi - lo) * 0.05).max(1e-9);
    (lo - pad)..(hi + pad)
}

/// Fig. 2: the reference (dashed) and actual deformation of the first identification run of each surface.
pub fn identification(runs: &[&SurfaceRun], out: &Path) -> Result<PathBuf> {
    let path = out.join("fig2_identification.svg");
    let root = SVGBackend::new(&path, (1000, 300 * runs.len() as u32)).into_drawing_area();
    root.fill(&WHITE)?;
    for (run, area) in runs.iter().zip(root.split_evenly((runs.len(), 1))) {
        let s = &run.identification;
        let t0 = s.time.first().copied().unwrap_or(0.0);
        let mm = |v: &f64| v * 1e3;
        let y = range(s.z.iter().chain(&s.z_cmd).map(mm));
        let end = s.time.last().map_or(1.0, |t| t - t0);
        // Room on the right for the legend, clear of the data.
        let mut chart = ChartBuilder::on(&area)
            .caption(format!("{}: identification run 1 (simulation)", run.spec.name), ("sans-serif", 18))
            .margin(10)
            .x_label_area_size(35)
            .y_label_area_size(55)
            .build_cartesian_2d(0.0..end * 1.3, y)?;
        chart.configure_mesh().x_desc("time [s]").y_desc("deformation z [mm]").draw()?;
        chart
            .draw_series(DashedLineSeries::new(
                s.time.iter().zip(&s.z_cmd).map(|(t, z)| (t - t0, mm(z))),
                6,
                4,
                BLUE.stroke_width(1),
            ))?
            .label("reference")
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLUE));
        chart
            .draw_series(LineSeries::new(s.time.iter().zip(&s.z).map(|(t, z)| (t - t0, mm(z))), BLACK))?
            .label("actual")
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLACK));
        chart
            .draw_series(LineSeries::new(vec![(0.0, 0.0), (end, 0.0)], RED))?
            .label("surface at contact (onset, 1 N)")
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], RED));
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperRight)
            .border_style(BLACK)
            .background_style(WHITE.mix(0.8))
            .draw()?;
    }
    root.present()?;
    Ok(path.clone())
}

/// Figs. 3 and 4: actual, predicted and commanded normal force over the control experiment through
/// the model `use_` (the identified one: the force-control paper's figure; the augmented one: `_augmented`), the five
/// cycles separated by dashed red lines.
pub fn control(run: &SurfaceRun, use_: ModelUse, figure: u32, out: &Path) -> Result<PathBuf> {
    let (control, suffix, which) = match (use_, &run.augmented) {
        (ModelUse::Augmented, Some((_, control))) => (control, "_augmented", "cycle 1 through the augmented model"),
        _ => (&run.control, "", "cycle 1 through the identified model"),
    };
    let path = out.join(format!("fig{figure}_control_{}{suffix}.svg", run.spec.name));
    let root = SVGBackend::new(&path, (1200, 450)).into_drawing_area();
    root.fill(&WHITE)?;
    let s = &control.series;
    let command_times = &control.command_times;
    let commands: Vec<_> = run.commands.iter().filter(|c| c.model == use_).collect();
    let t0 = command_times.first().copied().unwrap_or(0.0);
    let t1 = s.time.last().map_or(1.0, |t| t - t0);
    let y = range(s.force.iter().chain(&s.predicted).copied().chain([0.0]));
    let mut chart = ChartBuilder::on(&root)
        .caption(
            format!("{}: actual, predicted and command normal force, {which} (simulation)", run.spec.name),
            ("sans-serif", 18),
        )
        .margin(10)
        .x_label_area_size(35)
        .y_label_area_size(55)
        .build_cartesian_2d(0.0..t1, y.clone())?;
    chart.configure_mesh().x_desc("time [s]").y_desc("normal force [N]").draw()?;
    for (i, t) in command_times.iter().enumerate().filter(|(i, _)| i % 6 == 0 && *i > 0) {
        let _ = i;
        chart.draw_series(DashedLineSeries::new(
            vec![(t - t0, y.start), (t - t0, y.end)],
            5,
            5,
            RED.stroke_width(1),
        ))?;
    }
    chart
        .draw_series(DashedLineSeries::new(
            s.time.iter().zip(&s.predicted).map(|(t, f)| (t - t0, *f)),
            6,
            4,
            BLUE.stroke_width(1),
        ))?
        .label("predicted by the model in use")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLUE));
    chart
        .draw_series(LineSeries::new(s.time.iter().zip(&s.force).map(|(t, f)| (t - t0, *f)), BLACK))?
        .label("actual")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLACK));
    chart
        .draw_series(
            command_times
                .iter()
                .zip(&commands)
                .map(|(t, c)| Circle::new((t - t0 + 2.0, c.command), 4, GREEN.stroke_width(2))),
        )?
        .label("command (end of each move)")
        .legend(|(x, y)| Circle::new((x + 10, y), 4, GREEN.stroke_width(2)));
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::LowerLeft)
        .border_style(BLACK)
        .background_style(WHITE.mix(0.8))
        .draw()?;
    root.present()?;
    Ok(path.clone())
}
