//! The discrepancy workflow on loading-path recordings (the snake paper, "Frictional Compliance Model
//! Development and Experiments for Snake Robot Climbing", section IV): contact episodes, each zeroed where the paper zeroes it,
//! with both force channels — the normal force P and the tangential force T along the episode's axis.
//!
//! The snake paper names its two worst errors and cannot model a third thing it measured:
//! - `contact_offset_drift`: the specimen's zero creeps during an experiment (by a different amount each
//!   time), so P falls short of Hertz's law by 1.5 k_n √z · c_i · s, growing with the progress s along the
//!   path — one creep c_i per episode;
//! - `sensor_crosstalk`: the sensor's axes turned by ε from the pushing axes in the loading plane, so the
//!   readings mix, P' = P − ε T and T' = T + ε P (small angles);
//! - `tangential_history`: the tangential force depends on the path taken (Mindlin–Deresiewicz), where
//!   Walton's law has one force per (δ_n, δ_t).
//!
//! The model is linear in its amplitudes once Hertz's zero depth z_0 is fixed (fitted with k_n first:
//! `fit_normal_stiffness_and_zero`): P = k_n z^{3/2} + 1.5 k_n √z d_i and T = k_t h(path) + k_t √z e_i,
//! with each episode's own zero errors always in — d_i along the normal (a zero found at the third reading
//! above a threshold lies a little deeper or shallower each time; it moves T too, by k_t δ_t d_i / (2√z))
//! and e_i across it (found after some travel along an inclined path: Walton's T gains k_t √z e_i, the
//! incremental law's keeps the 1.5 k_t √z_0 e_i that travel loaded) — and h = √z δ_t (Walton) or the
//! incremental law's response to unit k_t along the
//! episode (linearised about the law fitted to the episodes, its microslip included); the candidates add
//! their columns. Every structure is solved by least squares
//! over both channels (normal equations, sparse by episode). A candidate is named when, against the model
//! so far, it lowers the residual by at least [`PathOptions::min_gain`], its AICc by at least
//! [`PathOptions::min_delta_aicc`] and — for the crosstalk's one amplitude — its |t| is at least
//! [`PathOptions::min_t`]; the best passing candidate is added and the rest are tried again. Nothing
//! passing: nothing is named.

use nalgebra::{DMatrix, DVector};
use serde::Serialize;
use softcontact_contact::{
    ContactError, MindlinDeresiewicz, PathSample, Tangential, fit_normal_stiffness_and_zero, identify_tangential,
    with_hertz,
};

/// The deepest an episode's zero is searched for below the surface [m].
const MAX_ZERO_DEPTH: f64 = 100e-6;

/// When a candidate is named.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct PathOptions {
    /// Relative drop of the residual's sum of squares.
    pub min_gain: f64,
    /// Drop of AICc.
    pub min_delta_aicc: f64,
    /// |t| of a single amplitude.
    pub min_t: f64,
}

impl Default for PathOptions {
    fn default() -> Self {
        Self { min_gain: 0.02, min_delta_aicc: 10.0, min_t: 4.0 }
    }
}

/// The candidates, by their canonical ids.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum PathEffect {
    ContactOffsetDrift,
    SensorCrosstalk,
    TangentialHistory,
}

impl PathEffect {
    pub const ALL: [PathEffect; 3] =
        [PathEffect::ContactOffsetDrift, PathEffect::SensorCrosstalk, PathEffect::TangentialHistory];

    pub fn id(self) -> &'static str {
        match self {
            PathEffect::ContactOffsetDrift => "contact_offset_drift",
            PathEffect::SensorCrosstalk => "sensor_crosstalk",
            PathEffect::TangentialHistory => "tangential_history",
        }
    }
}

/// One round's evidence for the candidate it named.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PathNamed {
    pub effect: PathEffect,
    /// Relative drop of the residual sum of squares, and of AICc.
    pub gain: f64,
    pub delta_aicc: f64,
}

/// What the workflow found.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PathReport {
    pub episodes: usize,
    pub samples: usize,
    /// Hertz's k_n [N/m^{3/2}] and how far below the surface the zeros lie \[m\].
    pub k_n: f64,
    pub zero_depth: f64,
    /// The effects named, in the order they were.
    pub named: Vec<PathNamed>,
    /// The final model's parameters: k_t [N/m^{3/2}]; the misalignment ε \[rad\] (0 unless named); the
    /// creep of the zero per episode, mean and standard deviation \[m\] (0 unless named).
    pub k_t: f64,
    pub misalignment: f64,
    pub creep_mean: f64,
    pub creep_sd: f64,
    /// RMS of the residual \[N\] of the normal and tangential channels, before (the baseline) and after.
    pub rms_before: [f64; 2],
    pub rms_after: [f64; 2],
}

impl PathReport {
    pub fn names(&self) -> Vec<&'static str> {
        self.named.iter().map(|n| n.effect.id()).collect()
    }
}

/// One row of the least-squares problem: its non-zero entries and its target.
struct Row {
    entries: Vec<(usize, f64)>,
    y: f64,
    tangential: bool,
}

/// A structure's fit: its sum of squares per channel, its parameters and their standard errors.
struct Solved {
    sse: [f64; 2],
    beta: DVector<f64>,
    se: DVector<f64>,
}

/// The data prepared once: z, the progress s, the measured P and T, and both laws' unit responses.
struct Prepared {
    episodes: Vec<Vec<Point>>,
    k_n: f64,
    /// Walton's k_t of a first fit, for how an episode's zero error moves its tangential force.
    k_t: f64,
}

struct Point {
    z: f64,
    progress: f64,
    p: f64,
    t: f64,
    walton: f64,
    incremental: f64,
}

/// Names what a set of loading-path episodes shows beyond Hertz + Walton (each episode's samples from its
/// zero, normal and tangential forces as measured).
pub fn name_path_effects(episodes: &[Vec<PathSample>], options: &PathOptions) -> Result<PathReport, ContactError> {
    let episodes: Vec<&Vec<PathSample>> = episodes.iter().filter(|e| e.len() >= 2).collect();
    if episodes.len() < 2 {
        return Err(ContactError::NotEnoughData { kind: "loading-path discrepancy (at least two episodes)" });
    }
    let normal: Vec<(f64, f64)> =
        episodes.iter().flat_map(|e| e.iter().map(|s| (s.normal_displacement, s.normal_force))).collect();
    let (k_n, zero_depth) = fit_normal_stiffness_and_zero(&normal, MAX_ZERO_DEPTH)?;
    // The incremental law's response per unit k_t, with the friction it shows (microslip on the paths'
    // sideways segments): both from the law fitted to these episodes (`identify_tangential`), the
    // response linear in k_t about that fit.
    let owned: Vec<Vec<PathSample>> = episodes.iter().map(|e| e.to_vec()).collect();
    let law = identify_tangential(&with_hertz(&owned, k_n, zero_depth), 5)?.mindlin_deresiewicz.law;
    if law.stiffness.is_nan() || law.stiffness <= 0.0 {
        return Err(ContactError::NotEnoughData { kind: "loading-path discrepancy (no tangential stiffness)" });
    }
    let mut prepared = Prepared::new(&episodes, k_n, zero_depth, &law)?;
    let samples: usize = prepared.episodes.iter().map(Vec::len).sum();
    prepared.k_t = prepared.solve(&[])?.beta[1];
    let base = prepared.solve(&[])?;
    let base_sse = base.sse;
    let (structure, last, named) = prepared.select(base, options)?;
    let n = episodes.len();
    let creep: Vec<f64> = if structure.contains(&PathEffect::ContactOffsetDrift) {
        let first = prepared.column_of(&structure, PathEffect::ContactOffsetDrift);
        (0..n).map(|i| last.beta[first + i]).collect()
    } else {
        vec![0.0; n]
    };
    let mean = creep.iter().sum::<f64>() / n as f64;
    let sd = (creep.iter().map(|c| (c - mean).powi(2)).sum::<f64>() / (n - 1) as f64).sqrt();
    let per_channel = samples as f64;
    Ok(PathReport {
        episodes: n,
        samples,
        k_n,
        zero_depth,
        named,
        k_t: last.beta[1],
        misalignment: if structure.contains(&PathEffect::SensorCrosstalk) {
            last.beta[prepared.column_of(&structure, PathEffect::SensorCrosstalk)]
        } else {
            0.0
        },
        creep_mean: mean,
        creep_sd: sd,
        rms_before: [(base_sse[0] / per_channel).sqrt(), (base_sse[1] / per_channel).sqrt()],
        rms_after: [(last.sse[0] / per_channel).sqrt(), (last.sse[1] / per_channel).sqrt()],
    })
}

impl Prepared {
    /// Each episode's points: the depth below the fitted zero, the Walton and incremental responses per
    /// unit k_t (the incremental law restarted at each lift-off).
    fn new(episodes: &[&Vec<PathSample>], k_n: f64, zero_depth: f64, law: &Tangential) -> Result<Self, ContactError> {
        let mut prepared = Prepared { episodes: Vec::with_capacity(episodes.len()), k_n, k_t: 0.0 };
        for e in episodes {
            let mut md = MindlinDeresiewicz::default();
            let last = (e.len() - 1) as f64;
            let mut points = Vec::with_capacity(e.len());
            for (j, s) in e.iter().enumerate() {
                let z = s.normal_displacement + zero_depth;
                let (walton, incremental) = if z > 0.0 {
                    let p = k_n * z.powf(1.5);
                    (
                        z.sqrt() * s.tangential_displacement,
                        md.step(law, z, s.tangential_displacement, p)?.0 / law.stiffness,
                    )
                } else {
                    md = MindlinDeresiewicz::default();
                    (0.0, 0.0)
                };
                for v in [s.normal_force, s.tangential_force, walton, incremental] {
                    if !v.is_finite() {
                        return Err(ContactError::NonFinite { name: "loading-path sample", value: v });
                    }
                }
                points.push(Point {
                    z,
                    progress: j as f64 / last,
                    p: s.normal_force,
                    t: s.tangential_force,
                    walton,
                    incremental,
                });
            }
            prepared.episodes.push(points);
        }
        Ok(prepared)
    }

    /// Forward selection from `base`: each round adds the candidate with the largest AICc gain that
    /// passes the gates; returns the structure, its fit and what was named.
    fn select(
        &self,
        base: Solved,
        options: &PathOptions,
    ) -> Result<(Vec<PathEffect>, Solved, Vec<PathNamed>), ContactError> {
        let mut structure: Vec<PathEffect> = Vec::new();
        let mut current = base;
        let mut named = Vec::new();
        loop {
            let mut best: Option<(PathEffect, f64, f64, Solved)> = None;
            for candidate in PathEffect::ALL.into_iter().filter(|c| !structure.contains(c)) {
                let mut trial = structure.clone();
                trial.push(candidate);
                let solved = self.solve(&trial)?;
                let (before, after) = (current.sse[0] + current.sse[1], solved.sse[0] + solved.sse[1]);
                let gain = 1.0 - after / before;
                let delta_aicc = self.aicc(before, &structure) - self.aicc(after, &trial);
                let t_ok = match candidate {
                    PathEffect::SensorCrosstalk => {
                        let i = self.column_of(&trial, candidate);
                        (solved.beta[i] / solved.se[i]).abs() >= options.min_t
                    }
                    _ => true,
                };
                if gain >= options.min_gain
                    && delta_aicc >= options.min_delta_aicc
                    && t_ok
                    && best.as_ref().is_none_or(|b| delta_aicc > b.2)
                {
                    best = Some((candidate, gain, delta_aicc, solved));
                }
            }
            // The named candidate's fit is the model from now on (its structure adds it last, as tried).
            let Some((effect, gain, delta_aicc, solved)) = best else { break };
            structure.push(effect);
            current = solved;
            named.push(PathNamed { effect, gain, delta_aicc });
        }
        Ok((structure, current, named))
    }
}

impl Prepared {
    /// Columns: k_n, k_t, one zero error per episode (normal), one per episode (tangential), then each
    /// effect of `structure` in its order (drift: one per episode; crosstalk: one).
    fn columns(&self, structure: &[PathEffect]) -> usize {
        let n = self.episodes.len();
        2 + 2 * n
            + structure
                .iter()
                .map(|e| match e {
                    PathEffect::ContactOffsetDrift => n,
                    PathEffect::SensorCrosstalk => 1,
                    PathEffect::TangentialHistory => 0,
                })
                .sum::<usize>()
    }

    fn column_of(&self, structure: &[PathEffect], effect: PathEffect) -> usize {
        let n = self.episodes.len();
        let mut column = 2 + 2 * n;
        for e in structure {
            if *e == effect {
                return column;
            }
            column += match e {
                PathEffect::ContactOffsetDrift => n,
                PathEffect::SensorCrosstalk => 1,
                PathEffect::TangentialHistory => 0,
            };
        }
        column
    }

    /// AICc of a structure with residual sum of squares `sse` (Gaussian residuals, both channels).
    fn aicc(&self, sse: f64, structure: &[PathEffect]) -> f64 {
        let n = 2.0 * self.episodes.iter().map(Vec::len).sum::<usize>() as f64;
        let k = self.columns(structure) as f64 + 1.0;
        n * (sse / n).ln() + 2.0 * k + 2.0 * k * (k + 1.0) / (n - k - 1.0).max(1.0)
    }

    fn rows(&self, structure: &[PathEffect]) -> Vec<Row> {
        let n = self.episodes.len();
        let history = structure.contains(&PathEffect::TangentialHistory);
        let drift = structure
            .contains(&PathEffect::ContactOffsetDrift)
            .then(|| self.column_of(structure, PathEffect::ContactOffsetDrift));
        let crosstalk = structure
            .contains(&PathEffect::SensorCrosstalk)
            .then(|| self.column_of(structure, PathEffect::SensorCrosstalk));
        let mut rows = Vec::new();
        for (i, episode) in self.episodes.iter().enumerate() {
            let origin_depth = episode.first().map_or(0.0, |p| p.z.max(0.0));
            for p in episode {
                let z = p.z.max(0.0);
                // ∂P/∂z = 1.5 k_n √z: a zero error d_i shifts every z of the episode; creep c_i grows with s.
                let slope = 1.5 * self.k_n * z.sqrt();
                let mut normal = vec![(0, z.powf(1.5)), (2 + i, slope)];
                if let Some(c) = drift {
                    normal.push((c + i, -slope * p.progress));
                }
                // The zero error moves the tangential force too: ∂T/∂z = k_t δ_t / (2√z) (Walton's).
                let lever = if z > 0.0 { 0.5 * self.k_t * p.walton / z } else { 0.0 };
                // A zero found after some travel along an inclined path: δ_t offset by e_i — Walton's T by
                // k_t √z e_i; the incremental law keeps what that travel loaded, 1.5 k_t √z_0 e_i.
                let offset = if history { 1.5 * self.k_t * origin_depth.sqrt() } else { self.k_t * z.sqrt() };
                let mut tangential =
                    vec![(1, if history { p.incremental } else { p.walton }), (2 + i, lever), (2 + n + i, offset)];
                if let Some(c) = crosstalk {
                    normal.push((c, -p.t));
                    tangential.push((c, p.p));
                }
                rows.push(Row { entries: normal, y: p.p, tangential: false });
                rows.push(Row { entries: tangential, y: p.t, tangential: true });
            }
        }
        debug_assert!(rows.iter().all(|r| r.entries.iter().all(|(c, _)| *c < self.columns(structure))), "{n}");
        rows
    }

    /// Least squares through the normal equations (each row has at most four entries).
    fn solve(&self, structure: &[PathEffect]) -> Result<Solved, ContactError> {
        let m = self.columns(structure);
        let rows = self.rows(structure);
        let mut ata = DMatrix::<f64>::zeros(m, m);
        let mut aty = DVector::<f64>::zeros(m);
        for r in &rows {
            for &(i, a) in &r.entries {
                aty[i] += a * r.y;
                for &(j, b) in &r.entries {
                    ata[(i, j)] += a * b;
                }
            }
        }
        // Columns the data leave empty (an episode without contact samples) are pinned at zero.
        for i in 0..m {
            if ata[(i, i)] == 0.0 {
                ata[(i, i)] = 1.0;
            }
        }
        let scale: DVector<f64> = ata.diagonal().map(|d| 1.0 / d.sqrt());
        let scaled = DMatrix::from_fn(m, m, |i, j| ata[(i, j)] * scale[i] * scale[j]);
        let cholesky = scaled
            .cholesky()
            .ok_or(ContactError::NotEnoughData { kind: "loading-path discrepancy (columns not independent)" })?;
        let beta = cholesky.solve(&aty.component_mul(&scale)).component_mul(&scale);
        let mut sse = [0.0; 2];
        for r in &rows {
            let fitted: f64 = r.entries.iter().map(|&(i, a)| a * beta[i]).sum();
            sse[usize::from(r.tangential)] += (r.y - fitted).powi(2);
        }
        let dof = (rows.len() as f64 - m as f64).max(1.0);
        let sigma2 = (sse[0] + sse[1]) / dof;
        let inverse = cholesky.inverse();
        let se = DVector::from_fn(m, |i, _| (sigma2 * inverse[(i, i)]).sqrt() * scale[i]);
        Ok(Solved { sse, beta, se })
    }
}
