//! Figures of `softcontact discrepancy`: the force residual over time before and after the model is
//! augmented, the force–deformation loops, and every sample as CSV. Drawing is decimated so that an SVG
//! stays small however long the recording; the CSV keeps every sample.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use anyhow::ensure;
use plotters::prelude::*;
use softcontact_discrepancy::{Phase, Series};

use crate::table::prefix;

/// What to draw: the recording along the normal and the two predictions.
pub struct Figures<'a> {
    /// Recording name, used in file names and titles.
    pub name: &'a str,
    /// t \[s\], z \[m\] (deformation from the refitted surface; negative = free space), zdot [m/s], f \[N\] measured.
    pub series: &'a Series,
    /// Phase of each sample.
    pub phases: &'a [Phase],
    /// Force predicted by the baseline model \[N\], per sample.
    pub before: &'a [f64],
    /// Force predicted by the augmented model \[N\], per sample.
    pub after: &'a [f64],
    /// σ \[N\].
    pub noise_floor: f64,
}

/// Buckets along time: a residual line has at most two points per bucket, a loop line at most this many.
const BUCKETS: usize = 2000;
/// Loop lines are strided, not min/max-bucketed (force against deformation has no time order to keep).
const MAX_LOOP_POINTS: usize = 2 * BUCKETS;

/// Writes `<name>.residual.svg` (residual measured − predicted over time, before and after, the ±σ noise
/// band, background shaded by phase with a legend), `<name>.loops.svg` (force against deformation:
/// measured, baseline and augmented, in-contact samples only) and `<name>.residual.csv` (columns t_s, z_m,
/// zdot_m_per_s, f_n, before_n, after_n, phase) into `out`; returns the paths written.
pub fn write(out: &Path, figures: &Figures) -> anyhow::Result<Vec<PathBuf>> {
    let n = figures.series.t.len();
    ensure!(n > 0, "{}: no samples to draw", figures.name);
    let s = figures.series;
    for (what, len) in [("z", s.z.len()), ("zdot", s.zdot.len()), ("f", s.f.len()), ("phases", figures.phases.len())]
        .into_iter()
        .chain([("before", figures.before.len()), ("after", figures.after.len())])
    {
        ensure!(len == n, "{}: {what} has {len} samples, t has {n}", figures.name);
    }
    Ok(vec![residual(out, figures)?, loops(out, figures)?, csv(out, figures)?])
}

/// Like demo::figures::range, ignoring non-finite values.
pub(crate) fn range(values: impl Iterator<Item = f64>) -> std::ops::Range<f64> {
    let (lo, hi) =
        values.filter(|v| v.is_finite()).fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| (lo.min(v), hi.max(v)));
    if lo > hi {
        return -1.0..1.0;
    }
    let pad = ((hi - lo) * 0.05).max(1e-9);
    (lo - pad)..(hi + pad)
}

/// The lowest and highest point of each bucket of `size` samples, in time order, so spikes survive.
fn min_max(t: &[f64], y: impl Fn(usize) -> f64, size: usize) -> Vec<(f64, f64)> {
    let mut points = Vec::with_capacity(2 * t.len().div_ceil(size));
    for start in (0..t.len()).step_by(size) {
        let (mut lo, mut hi) = (None, None);
        for (i, v) in (start..(start + size).min(t.len())).map(|i| (i, y(i))).filter(|p| p.1.is_finite()) {
            lo = lo.filter(|&(_, l)| l <= v).or(Some((i, v)));
            hi = hi.filter(|&(_, h)| h >= v).or(Some((i, v)));
        }
        if let (Some(lo), Some(hi)) = (lo, hi) {
            // Both extremes, in time order, so the line goes through the spike rather than across it.
            points.extend(if lo.0 <= hi.0 { [lo, hi] } else { [hi, lo] }.map(|(i, v)| (t[i], v)));
        }
    }
    points
}

/// Runs of one phase as (first sample, end sample exclusive, phase), at the resolution of buckets of
/// `size` samples: each bucket takes its most frequent phase, so flickering phases cannot multiply the
/// rectangles (at most one per bucket) and a run shorter than a bucket gives way to its neighbours.
fn phase_runs(phases: &[Phase], size: usize) -> Vec<(usize, usize, Phase)> {
    let mut runs: Vec<(usize, usize, Phase)> = Vec::new();
    for (bucket, chunk) in phases.chunks(size).enumerate() {
        let count = |p: &Phase| chunk.iter().filter(|q| *q == p).count();
        let phase = Phase::ALL.into_iter().max_by_key(count).expect("five phases");
        let (start, end) = (bucket * size, bucket * size + chunk.len());
        match runs.last_mut() {
            Some(last) if last.2 == phase => last.1 = end,
            _ => runs.push((start, end, phase)),
        }
    }
    runs
}

fn phase_color(phase: Phase) -> RGBColor {
    match phase {
        Phase::Free => RGBColor(200, 200, 200),
        Phase::Approach => RGBColor(160, 200, 255),
        Phase::Loading => RGBColor(255, 190, 120),
        Phase::Holding => RGBColor(150, 220, 150),
        Phase::Unloading => RGBColor(210, 160, 230),
    }
}

/// The largest magnitude, for the axes' SI prefix ([`prefix`]): the figures of a 1 nN AFM curve and of a
/// 100 N press both read in plain numbers.
fn largest(values: impl Iterator<Item = f64>) -> f64 {
    values.filter(|v| v.is_finite()).fold(0.0, |a, v| a.max(v.abs()))
}

fn phase_name(phase: Phase) -> String {
    format!("{phase:?}").to_lowercase()
}

fn residual(out: &Path, fig: &Figures) -> anyhow::Result<PathBuf> {
    let path = out.join(format!("{}.residual.svg", fig.name));
    let s = fig.series;
    let t0 = s.t[0];
    let t: Vec<f64> = s.t.iter().map(|t| t - t0).collect();
    let end = t[t.len() - 1].max(1e-9);
    let size = t.len().div_ceil(BUCKETS);
    let (unit, scale) = prefix(largest((0..t.len()).map(|i| s.f[i] - fig.before[i])).max(fig.noise_floor));
    let before = min_max(&t, |i| (s.f[i] - fig.before[i]) / scale, size);
    let after = min_max(&t, |i| (s.f[i] - fig.after[i]) / scale, size);
    let sigma = fig.noise_floor / scale;
    let y = range(before.iter().chain(&after).map(|p| p.1).chain([-sigma, sigma]));

    let root = SVGBackend::new(&path, (1200, 450)).into_drawing_area();
    root.fill(&WHITE)?;
    // Room on the right for the legend, clear of the data.
    let mut chart = ChartBuilder::on(&root)
        .caption(format!("{}: force residual, measured − predicted", fig.name), ("sans-serif", 18))
        .margin(10)
        .x_label_area_size(35)
        .y_label_area_size(55)
        .build_cartesian_2d(0.0..end * 1.25, y.clone())?;
    chart.configure_mesh().x_desc("time [s]").y_desc(format!("residual force [{unit}N]")).draw()?;
    let runs = phase_runs(fig.phases, size);
    for phase in Phase::ALL.into_iter().filter(|p| runs.iter().any(|r| r.2 == *p)) {
        let color = phase_color(phase).mix(0.35);
        let x = |i: usize| t[i.min(t.len() - 1)];
        let rects = runs.iter().filter(|r| r.2 == phase);
        chart
            .draw_series(rects.map(|r| Rectangle::new([(x(r.0), y.start), (x(r.1), y.end)], color.filled())))?
            .label(phase_name(phase))
            .legend(move |(x, y)| Rectangle::new([(x, y - 5), (x + 20, y + 5)], color.filled()));
    }
    let band = BLACK.mix(0.15);
    chart
        .draw_series([Rectangle::new([(0.0, -sigma), (end, sigma)], band.filled())])?
        .label(format!("±σ noise floor ({sigma:.3} {unit}N)"))
        .legend(move |(x, y)| Rectangle::new([(x, y - 5), (x + 20, y + 5)], band.filled()));
    chart
        .draw_series(LineSeries::new(before, RED))?
        .label("before (baseline model)")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], RED));
    chart
        .draw_series(LineSeries::new(after, BLUE))?
        .label("after (augmented model)")
        .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], BLUE));
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .border_style(BLACK)
        .background_style(WHITE.mix(0.8))
        .draw()?;
    root.present()?;
    Ok(path.clone())
}

/// Every `stride`-th in-contact sample of `y` against z, both divided by their scales, split where
/// contact was lost so that no line jumps across free space.
fn contact_segments(fig: &Figures, y: &[f64], stride: usize, (zs, fs): (f64, f64)) -> Vec<Vec<(f64, f64)>> {
    let mut segments: Vec<Vec<(f64, f64)>> = Vec::new();
    let mut previous = None;
    let contact = (0..y.len()).filter(|&i| fig.phases[i].in_contact());
    for i in contact.step_by(stride).filter(|&i| y[i].is_finite()) {
        let joined = previous.is_some_and(|p| (p..i).all(|j| fig.phases[j].in_contact()));
        if !joined {
            segments.push(Vec::new());
        }
        segments.last_mut().expect("pushed above").push((fig.series.z[i] / zs, y[i] / fs));
        previous = Some(i);
    }
    segments
}

fn loops(out: &Path, fig: &Figures) -> anyhow::Result<PathBuf> {
    let path = out.join(format!("{}.loops.svg", fig.name));
    let stride = fig.phases.iter().filter(|p| p.in_contact()).count().div_ceil(MAX_LOOP_POINTS).max(1);
    let contact = || (0..fig.phases.len()).filter(|&i| fig.phases[i].in_contact());
    let (z_unit, zs) = prefix(largest(contact().map(|i| fig.series.z[i])));
    let (f_unit, fs) = prefix(largest(contact().map(|i| fig.series.f[i])));
    let lines = [
        (contact_segments(fig, &fig.series.f, stride, (zs, fs)), BLACK.mix(0.5).stroke_width(3), "measured"),
        (contact_segments(fig, fig.before, stride, (zs, fs)), RED.stroke_width(1), "baseline model"),
        (contact_segments(fig, fig.after, stride, (zs, fs)), BLUE.stroke_width(1), "augmented model"),
    ];
    let points = || lines.iter().flat_map(|l| l.0.iter().flatten());
    let root = SVGBackend::new(&path, (800, 600)).into_drawing_area();
    root.fill(&WHITE)?;
    let mut chart = ChartBuilder::on(&root)
        .caption(format!("{}: force against deformation, in contact", fig.name), ("sans-serif", 18))
        .margin(10)
        .x_label_area_size(35)
        .y_label_area_size(55)
        .build_cartesian_2d(range(points().map(|p| p.0)), range(points().map(|p| p.1).chain([0.0])))?;
    chart
        .configure_mesh()
        .x_desc(format!("deformation z [{z_unit}m]"))
        .y_desc(format!("normal force [{f_unit}N]"))
        .draw()?;
    for (segments, style, label) in &lines {
        let style = *style;
        chart
            .draw_series(segments.iter().map(|s| PathElement::new(s.clone(), style)))?
            .label(*label)
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], style));
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperLeft)
        .border_style(BLACK)
        .background_style(WHITE.mix(0.8))
        .draw()?;
    root.present()?;
    Ok(path.clone())
}

fn csv(out: &Path, fig: &Figures) -> anyhow::Result<PathBuf> {
    let path = out.join(format!("{}.residual.csv", fig.name));
    let mut w = BufWriter::new(File::create(&path)?);
    writeln!(w, "t_s,z_m,zdot_m_per_s,f_n,before_n,after_n,phase")?;
    let s = fig.series;
    for i in 0..s.t.len() {
        let phase = phase_name(fig.phases[i]);
        writeln!(w, "{},{},{},{},{},{},{phase}", s.t[i], s.z[i], s.zdot[i], s.f[i], fig.before[i], fig.after[i])?;
    }
    w.flush()?;
    Ok(path)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Sinusoidal pushes at 1 kHz with phases that flicker every 3 samples in contact (the worst case for
    /// the shading) and one force spike.
    fn synthetic(n: usize) -> (Series, Vec<Phase>, Vec<f64>, Vec<f64>) {
        let t: Vec<f64> = (0..n).map(|i| i as f64 * 1e-3).collect();
        let z: Vec<f64> = t.iter().map(|t| 0.004 * (std::f64::consts::TAU * 0.5 * t).sin() - 0.001).collect();
        let zdot: Vec<f64> =
            t.iter().map(|t| 0.004 * std::f64::consts::PI * (std::f64::consts::TAU * 0.5 * t).cos()).collect();
        let before: Vec<f64> = z.iter().map(|z| 2000.0 * z.max(0.0)).collect();
        let after: Vec<f64> =
            before.iter().zip(&zdot).map(|(f, v)| if *f > 0.0 { f + 50.0 * v } else { 0.0 }).collect();
        let mut f: Vec<f64> =
            after.iter().enumerate().map(|(i, f)| f + 0.05 * ((i * 7919) % 13) as f64 / 13.0).collect();
        f[n / 2] += 30.0;
        let phases = z
            .iter()
            .enumerate()
            .map(|(i, z)| match (*z > 0.0, i / 3 % 3) {
                (false, 0) => Phase::Approach,
                (false, _) => Phase::Free,
                (true, 0) => Phase::Loading,
                (true, 1) => Phase::Holding,
                (true, _) => Phase::Unloading,
            })
            .collect();
        (Series::new(t, z, zdot, f).unwrap(), phases, before, after)
    }

    fn write_synthetic(n: usize, dir: &Path) -> Vec<PathBuf> {
        let (series, phases, before, after) = synthetic(n);
        let figures = Figures {
            name: "synthetic",
            series: &series,
            phases: &phases,
            before: &before,
            after: &after,
            noise_floor: 0.05,
        };
        write(dir, &figures).unwrap()
    }

    #[test]
    fn writes_svgs_and_every_sample_as_csv() {
        let dir = tempfile::tempdir().unwrap();
        let paths = write_synthetic(5000, dir.path());
        let names: Vec<_> = paths.iter().map(|p| p.file_name().unwrap().to_str().unwrap()).collect();
        assert_eq!(names, ["synthetic.residual.svg", "synthetic.loops.svg", "synthetic.residual.csv"]);
        for svg in &paths[..2] {
            let text = std::fs::read_to_string(svg).unwrap();
            assert!(text.trim_start().starts_with("<svg") && text.trim_end().ends_with("</svg>"), "{svg:?}");
        }
        let csv = std::fs::read_to_string(&paths[2]).unwrap();
        let lines: Vec<_> = csv.lines().collect();
        assert_eq!(lines[0], "t_s,z_m,zdot_m_per_s,f_n,before_n,after_n,phase");
        assert_eq!(lines.len(), 5001);
        assert!(lines[1..].iter().all(|l| l.split(',').count() == 7));
    }

    #[test]
    fn long_recordings_stay_small_and_keep_spikes() {
        let dir = tempfile::tempdir().unwrap();
        let n = 300_000;
        let paths = write_synthetic(n, dir.path());
        for svg in &paths[..2] {
            let size = std::fs::metadata(svg).unwrap().len();
            assert!(size < 5_000_000, "{svg:?} is {size} bytes");
        }
        assert_eq!(std::fs::read_to_string(&paths[2]).unwrap().lines().count(), n + 1);
        let (series, phases, _, after) = synthetic(n);
        let size = n.div_ceil(BUCKETS);
        let residual = min_max(&series.t, |i| series.f[i] - after[i], size);
        assert!(residual.len() <= 2 * BUCKETS && residual.iter().any(|p| p.1 > 29.0));
        let runs = phase_runs(&phases, size);
        assert!(
            runs.len() <= BUCKETS && runs.iter().any(|r| r.2.in_contact()) && runs.iter().any(|r| !r.2.in_contact())
        );
    }
}
