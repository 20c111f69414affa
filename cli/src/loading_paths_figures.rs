//! Figures of `softcontact loading-paths`, like the snake paper's Figs. 4–8: the loading paths in the (δ_t, δ_n)
//! plane, the normal-loading data with the k_n fit, the linear-path data with the k_n and k_t fits, and
//! the forces at the convergence points beside what the fitted Mindlin–Deresiewicz law predicts there.
//! Each experiment is drawn with at most `PER_EXPERIMENT` points, so the SVGs stay small.

use std::path::{Path, PathBuf};

use plotters::coord::Shift;
use plotters::prelude::*;
use softcontact_contact::{ContactModel, Family, Kind, LoadingPath, Tangential, forces_at_end};
use softcontact_sim::BenchRun;

use crate::discrepancy_figures::range;

/// Fitted constants [N/m^{3/2}].
pub struct Fits {
    pub k_n_normal: f64,
    pub k_n_linear: f64,
    pub k_t_linear: f64,
}

const PER_EXPERIMENT: usize = 60;
const SET_COLORS: [RGBColor; 3] = [RGBColor(200, 40, 40), RGBColor(40, 120, 40), RGBColor(40, 60, 200)];

/// Writes `loading_paths.paths.svg`, `.normal.svg`, `.linear.svg` and `.convergence.svg` into `out`.
pub fn write(out: &Path, paths: &[LoadingPath], runs: &[BenchRun], fits: &Fits) -> anyhow::Result<Vec<PathBuf>> {
    anyhow::ensure!(paths.len() == runs.len(), "{} paths but {} runs", paths.len(), runs.len());
    Ok(vec![
        path_figure(out, paths)?,
        normal_figure(out, paths, runs, fits)?,
        linear_figure(out, paths, runs, fits)?,
        convergence_figure(out, paths, runs, fits)?,
    ])
}

/// Every experiment of `family`, each thinned to at most `PER_EXPERIMENT` samples, as (x, y).
fn thinned<'a>(
    paths: &'a [LoadingPath],
    runs: &'a [BenchRun],
    family: Family,
    xy: impl Fn(&softcontact_sim::BenchSample) -> (f64, f64) + 'a,
) -> Vec<(f64, f64)> {
    paths
        .iter()
        .zip(runs)
        .filter(|(p, _)| p.family == family)
        .flat_map(|(_, r)| {
            let stride = r.samples.len().div_ceil(PER_EXPERIMENT).max(1);
            r.samples.iter().step_by(stride).map(&xy).collect::<Vec<_>>()
        })
        .collect()
}

fn file(out: &Path, name: &str) -> PathBuf {
    out.join(format!("loading_paths.{name}.svg"))
}

/// Fig. 5 and 7: the paths of the linear and two-segment families \[mm\].
fn path_figure(out: &Path, paths: &[LoadingPath]) -> anyhow::Result<PathBuf> {
    let path = file(out, "paths");
    let root = SVGBackend::new(&path, (800, 600)).into_drawing_area();
    root.fill(&WHITE)?;
    let lines: Vec<(Vec<(f64, f64)>, RGBColor)> = paths
        .iter()
        .filter_map(|p| {
            let color = match p.family {
                Family::Normal => return None,
                Family::Linear => RGBColor(150, 150, 150),
                Family::TwoSegment(set) => SET_COLORS[set as usize - 1],
            };
            let points = std::iter::once([0.0, 0.0]).chain(p.waypoints.iter().copied());
            Some((points.map(|[dn, dt]| (dt * 1e3, dn * 1e3)).collect(), color))
        })
        .collect();
    let all = || lines.iter().flat_map(|l| l.0.iter());
    let mut chart = ChartBuilder::on(&root)
        .caption("Loading paths: linear (grey), two-segment sets 1, 2, 3 (red, green, blue)", ("sans-serif", 16))
        .margin(10)
        .x_label_area_size(35)
        .y_label_area_size(50)
        .build_cartesian_2d(range(all().map(|p| p.0)), range(all().map(|p| p.1)))?;
    chart.configure_mesh().x_desc("tangential displacement δt [mm]").y_desc("normal displacement δn [mm]").draw()?;
    for (points, color) in lines {
        chart.draw_series(std::iter::once(PathElement::new(points, color.stroke_width(1))))?;
    }
    root.present()?;
    Ok(path.clone())
}

fn scatter_with_fit(
    area: &DrawingArea<SVGBackend, Shift>,
    title: &str,
    (x_desc, y_desc): (&str, &str),
    points: &[(f64, f64)],
    fit: impl Fn(f64) -> f64,
) -> anyhow::Result<()> {
    let x = range(points.iter().map(|p| p.0).chain([0.0]));
    let y = range(points.iter().map(|p| p.1).chain([0.0]));
    let mut chart = ChartBuilder::on(area)
        .caption(title, ("sans-serif", 15))
        .margin(10)
        .x_label_area_size(35)
        .y_label_area_size(50)
        .build_cartesian_2d(x.clone(), y)?;
    chart.configure_mesh().x_desc(x_desc).y_desc(y_desc).draw()?;
    chart.draw_series(points.iter().map(|&p| Circle::new(p, 2, BLACK.mix(0.4).filled())))?;
    let line: Vec<(f64, f64)> = (0..=100)
        .map(|k| x.start.max(0.0) + (x.end - x.start.max(0.0)) * k as f64 / 100.0)
        .map(|v| (v, fit(v)))
        .collect();
    chart.draw_series(std::iter::once(PathElement::new(line, RED.stroke_width(2))))?;
    Ok(())
}

/// Fig. 4: normal loadings and the k_n fit.
fn normal_figure(out: &Path, paths: &[LoadingPath], runs: &[BenchRun], fits: &Fits) -> anyhow::Result<PathBuf> {
    let path = file(out, "normal");
    let root = SVGBackend::new(&path, (800, 600)).into_drawing_area();
    root.fill(&WHITE)?;
    let points = thinned(paths, runs, Family::Normal, |s| (s.normal_displacement * 1e3, s.normal_force));
    let k = fits.k_n_normal / softcontact_contact::N_PER_MM_1_5;
    let title = format!("Normal loadings and the fit k_n = {k:.3} N/mm^1.5");
    scatter_with_fit(&root, &title, ("δn [mm]", "normal force [N]"), &points, |dn| k * dn.max(0.0).powf(1.5))?;
    root.present()?;
    Ok(path.clone())
}

/// Fig. 6: linear paths, normal force against δn and f_t/√c against δt (c = δn/δt), with the fits.
fn linear_figure(out: &Path, paths: &[LoadingPath], runs: &[BenchRun], fits: &Fits) -> anyhow::Result<PathBuf> {
    let path = file(out, "linear");
    let root = SVGBackend::new(&path, (1200, 500)).into_drawing_area();
    root.fill(&WHITE)?;
    let (left, right) = root.split_horizontally(600);
    let per_mm = softcontact_contact::N_PER_MM_1_5;
    let (kn, kt) = (fits.k_n_linear / per_mm, fits.k_t_linear / per_mm);
    let normal = thinned(paths, runs, Family::Linear, |s| (s.normal_displacement * 1e3, s.normal_force));
    scatter_with_fit(
        &left,
        &format!("Linear paths, normal: k_n = {kn:.3}"),
        ("δn [mm]", "normal force [N]"),
        &normal,
        |dn| kn * dn.max(0.0).powf(1.5),
    )?;
    // f_t/√c = k_t δt^{3/2} along a ray (the snake paper's eq. 4).
    let tangential = thinned(paths, runs, Family::Linear, |s| {
        let c = s.normal_displacement / s.tangential_displacement;
        (s.tangential_displacement * 1e3, if c > 0.0 { s.tangential_force / c.sqrt() } else { f64::NAN })
    });
    scatter_with_fit(
        &right,
        &format!("Linear paths, tangential: k_t = {kt:.4}"),
        ("δt [mm]", "f_t / √c [N]"),
        &tangential,
        |dt| kt * dt.max(0.0).powf(1.5),
    )?;
    root.present()?;
    Ok(path.clone())
}

/// Fig. 8: the forces at the convergence points (end of every two-segment path), by set, with the
/// forces the Mindlin–Deresiewicz law fitted from the linear paths predicts there (crosses) and the
/// one force Walton's law predicts per point (black squares).
fn convergence_figure(out: &Path, paths: &[LoadingPath], runs: &[BenchRun], fits: &Fits) -> anyhow::Result<PathBuf> {
    let path = file(out, "convergence");
    let root = SVGBackend::new(&path, (800, 600)).into_drawing_area();
    root.fill(&WHITE)?;
    let mut md = ContactModel::new(Kind::HertzWalton, fits.k_n_linear, 0.0)?;
    md.tangential = Some(Tangential::mindlin_deresiewicz(fits.k_t_linear, 1e9));
    let mut walton = md.clone();
    walton.tangential = Some(Tangential::walton(fits.k_t_linear, 1e9));
    let mut measured = Vec::new();
    let mut predicted = Vec::new();
    let mut single = Vec::new();
    for (p, r) in paths.iter().zip(runs) {
        let Family::TwoSegment(set) = p.family else { continue };
        if let Some(end) = r.samples.last() {
            measured.push(((end.normal_force, end.tangential_force), set));
        }
        predicted.push((forces_at_end(&md, p, 50)?, set));
        single.push(forces_at_end(&walton, p, 1)?);
    }
    let all = || measured.iter().chain(&predicted).map(|p| p.0);
    let mut chart = ChartBuilder::on(&root)
        .caption("Convergence points: measured (dots), MD predicted (crosses), Walton (squares)", ("sans-serif", 15))
        .margin(10)
        .x_label_area_size(35)
        .y_label_area_size(50)
        .build_cartesian_2d(range(all().map(|p| p.0)), range(all().map(|p| p.1)))?;
    chart.configure_mesh().x_desc("normal force [N]").y_desc("tangential force [N]").draw()?;
    chart.draw_series(measured.iter().map(|&(p, set)| Circle::new(p, 3, SET_COLORS[set as usize - 1].filled())))?;
    chart.draw_series(
        predicted.iter().map(|&(p, set)| Cross::new(p, 4, SET_COLORS[set as usize - 1].stroke_width(1))),
    )?;
    chart.draw_series(
        single.iter().map(|&p| Rectangle::new([(p.0 - 0.08, p.1 - 0.02), (p.0 + 0.08, p.1 + 0.02)], BLACK.filled())),
    )?;
    root.present()?;
    Ok(path.clone())
}
