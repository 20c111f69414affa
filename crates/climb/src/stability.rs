//! Equilibria and their stability (the snake paper, section V, eq. 6: the contact model plugged into the
//! dynamics, linearised at the set point's equilibrium).
//!
//! - [`settle`]: the equilibrium as the physical squeeze reaches it — the snake simulated under its set
//!   point until it rests (feet may slide on the way, then stick). The equilibrium depends on that
//!   history: the tangential springs hold what the path left in them.
//! - [`refine`]: Newton's method on the static balance G(q) = τ_PD + Σ Jᵀf − g(q) = 0 from there, the
//!   feet's memories as the settling left them, to ‖G‖∞ ≤ 1e-10.
//! - [`linearize`]: ẋ = A x for x = (δq, δq̇), A = [0 I; M⁻¹ ∂G/∂q  M⁻¹ ∂G/∂q̇] (the ∂M⁻¹ term vanishes with
//!   G = 0, and h's velocity terms are quadratic). ∂G/∂q holds the contacts' stiffness, not symmetric
//!   (Walton's fₜ = kₜ √z δₜ depends on the depth), ~1e4 N/m against joint gains ~1 N m/rad: the matrix
//!   is balanced (Parlett–Reinsch, powers of two, eigenvalues unchanged) before the QR iteration. With the
//!   incremental law the tangent stiffness differs by direction (microslip while loading further, none
//!   while unloading): central differences take the mean.
//! - [`analyse`]: "stable" = the largest real part < −1e-3 s⁻¹ and a run from a perturbed start back
//!   within 1e-6 of the equilibrium.

use nalgebra::{Complex, DMatrix, DVector};
use serde::Serialize;

use crate::Error;
use crate::snake::{FootForce, Snake, State};

/// Integration step of every simulation \[s\]: a twentieth of the fastest contact period of the default
/// snake (≈ 2 ms at 1 mm depth).
pub const DT: f64 = 1e-4;
/// "Stable": the largest real part of the eigenvalues is below this [1/s].
pub const STABLE_REAL_PART: f64 = -1e-3;
/// "Stable": a perturbed run ends this close to the equilibrium [m, rad]. The run lasts 15 time
/// constants of the slowest mode but at most 10 s, so a mode decaying slower than about 0.23 1/s cannot
/// show its return within it and is reported as not back.
pub const RETURN_TOLERANCE: f64 = 1e-6;
/// The perturbation of that run [m, rad, infinity norm].
pub const PERTURBATION: f64 = 1e-5;

/// How a settling ended.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Settled {
    /// Simulated time to rest \[s\].
    pub time: f64,
    /// Whether every velocity fell below the rest speed (else the time limit ended it).
    pub at_rest: bool,
    /// How far each foot slid on the way \[m\].
    pub slip: Vec<f64>,
}

/// One step that also adds to `slip` how far each sliding foot moved along its wall.
pub fn step_counting_slip(
    snake: &Snake,
    state: &mut State,
    set_point: &[f64],
    slip: &mut [f64],
) -> Result<Vec<FootForce>, Error> {
    let before = snake.chain.node_positions(&state.q);
    let forces = snake.step(state, set_point, DT)?;
    let after = snake.chain.node_positions(&state.q);
    for (k, f) in forces.iter().enumerate() {
        if f.slides {
            slip[k] += (after[k].y - before[k].y).abs();
        }
    }
    Ok(forces)
}

/// Simulates the snake under a constant set point until every velocity stays below `rest_speed` [m/s,
/// rad/s] for 50 ms, or for `max_time` \[s\].
pub fn settle(snake: &Snake, state: &mut State, set_point: &[f64], max_time: f64) -> Result<Settled, Error> {
    let rest_speed = 1e-6;
    let (mut t, mut calm_since) = (0.0, 0.0);
    let mut slip = vec![0.0; state.feet.len()];
    while t < max_time {
        step_counting_slip(snake, state, set_point, &mut slip)?;
        t += DT;
        if state.dq.iter().any(|v| v.abs() > rest_speed) {
            calm_since = t;
        } else if t - calm_since >= 0.05 {
            break;
        }
    }
    Ok(Settled { time: t, at_rest: t - calm_since >= 0.05, slip })
}

/// G(q, q̇): the generalized forces but inertia, the feet's memories copied (left as they are).
fn static_forces(
    snake: &Snake,
    state: &State,
    q: &[f64],
    dq: &[f64],
    set_point: &[f64],
) -> Result<DVector<f64>, Error> {
    let mut feet = state.feet.clone();
    let (tau, _) = snake.applied_forces(q, dq, set_point, &mut feet)?;
    Ok(tau - snake.chain.nonlinear_effects(q, dq))
}

/// ∂G/∂q (`by_velocity` false) or ∂G/∂q̇ at the state, by central differences.
fn force_jacobian(snake: &Snake, state: &State, set_point: &[f64], by_velocity: bool) -> Result<DMatrix<f64>, Error> {
    let n = state.q.len();
    let h = 1e-7;
    let mut jac = DMatrix::zeros(n, n);
    for c in 0..n {
        let (mut plus, mut minus) = (state.clone(), state.clone());
        let (p, m) = if by_velocity { (&mut plus.dq, &mut minus.dq) } else { (&mut plus.q, &mut minus.q) };
        p[c] += h;
        m[c] -= h;
        let column = (static_forces(snake, state, &plus.q, &plus.dq, set_point)?
            - static_forces(snake, state, &minus.q, &minus.dq, set_point)?)
            / (2.0 * h);
        jac.set_column(c, &column);
    }
    Ok(jac)
}

/// Newton's method on G(q) = 0 at rest from the state's q; on success the state is moved there (at rest,
/// the feet's memories advanced) and the residual ‖G‖∞ [N, N m] is returned. A singular stiffness (a
/// motion no contact or joint resists) leaves the state as it was.
pub fn refine(snake: &Snake, state: &mut State, set_point: &[f64]) -> Result<f64, Error> {
    let zero = vec![0.0; state.q.len()];
    let mut trial = state.clone();
    trial.dq.fill(0.0);
    let mut residual = static_forces(snake, &trial, &trial.q, &zero, set_point)?;
    for _ in 0..30 {
        if residual.amax() <= 1e-10 {
            break;
        }
        let stiffness = force_jacobian(snake, &trial, set_point, false)?;
        let Some(step) = stiffness.lu().solve(&(-&residual)) else { break };
        for (q, d) in trial.q.iter_mut().zip(step.iter()) {
            *q += d;
        }
        residual = static_forces(snake, &trial, &trial.q, &zero, set_point)?;
    }
    let before = static_forces(snake, state, &state.q, &zero, set_point)?.amax();
    if residual.amax() < before {
        snake.applied_forces(&trial.q, &zero, set_point, &mut trial.feet)?;
        *state = trial;
    }
    Ok(residual.amax().min(before))
}

/// The closed loop linearised at an equilibrium (q̇ = 0): A (2n × 2n) with x = (δq, δq̇).
pub fn linearize(snake: &Snake, state: &State, set_point: &[f64]) -> Result<DMatrix<f64>, Error> {
    let n = state.q.len();
    let m = snake.chain.mass_matrix(&state.q);
    let chol = m.cholesky().expect("links with mass");
    let stiffness = chol.solve(&force_jacobian(snake, state, set_point, false)?);
    let damping = chol.solve(&force_jacobian(snake, state, set_point, true)?);
    let mut a = DMatrix::zeros(2 * n, 2 * n);
    a.view_mut((0, n), (n, n)).fill_with_identity();
    a.view_mut((n, 0), (n, n)).copy_from(&stiffness);
    a.view_mut((n, n), (n, n)).copy_from(&damping);
    Ok(a)
}

/// Balances a square matrix in place by a diagonal similarity of powers of two (Parlett and Reinsch,
/// "Balancing a matrix for calculation of eigenvalues and eigenvectors", 1969): each row and column get
/// comparable norms, so that the QR iteration's rounding is relative to the matrix's own scales. Returns
/// the scales d (A ← D⁻¹ A D).
pub fn balance(a: &mut DMatrix<f64>) -> Vec<f64> {
    let n = a.nrows();
    let mut scale = vec![1.0; n];
    loop {
        let mut converged = true;
        for i in 0..n {
            let c: f64 = (0..n).filter(|&j| j != i).map(|j| a[(j, i)].abs()).sum();
            let r: f64 = (0..n).filter(|&j| j != i).map(|j| a[(i, j)].abs()).sum();
            if c == 0.0 || r == 0.0 {
                continue;
            }
            // Scaling row i by 1/f and column i by f turns (c, r) into (c f, r / f): f ≈ √(r / c), a power of two.
            let (mut c2, mut f) = (c, 1.0);
            while c2 < r / 2.0 {
                c2 *= 4.0;
                f *= 2.0;
            }
            while c2 >= r * 2.0 {
                c2 /= 4.0;
                f /= 2.0;
            }
            // The pair's combined norm must fall noticeably, or the loop could go on forever.
            if (c * f + r / f) < 0.95 * (c + r) {
                converged = false;
                scale[i] *= f;
                for j in 0..n {
                    a[(i, j)] /= f;
                    a[(j, i)] *= f;
                }
            }
        }
        if converged {
            return scale;
        }
    }
}

/// Eigenvalues of a real square matrix, balanced first; sorted by real part, largest first.
pub fn eigenvalues(a: &DMatrix<f64>) -> Result<Vec<Complex<f64>>, Error> {
    let mut balanced = a.clone();
    balance(&mut balanced);
    let schur = nalgebra::Schur::try_new(balanced, f64::EPSILON, 10_000)
        .ok_or_else(|| Error::Analysis("the QR iteration did not converge".into()))?;
    let mut values: Vec<Complex<f64>> = schur.complex_eigenvalues().iter().copied().collect();
    values.sort_by(|a, b| b.re.total_cmp(&a.re));
    Ok(values)
}

/// The stability of one equilibrium.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Stability {
    /// The eigenvalue with the largest real part [1/s]: (re, im).
    pub slowest: (f64, f64),
    /// −Re λ / |λ| of that mode (1 for a real one).
    pub damping_ratio: f64,
    /// Every eigenvalue, (re, im), largest real part first.
    pub eigenvalues: Vec<(f64, f64)>,
    /// Distance [m, rad, infinity norm] from the equilibrium at the end of the run from a perturbed start.
    pub return_distance: f64,
    /// How long that run was \[s\], and its largest speed at the end [m/s, rad/s].
    pub return_time: f64,
    pub return_speed: f64,
    pub stable: bool,
}

/// Eigenvalues at the equilibrium and the run from a perturbed start (every coordinate moved by
/// ±[`PERTURBATION`], signs alternating). The run lasts long enough for the slowest mode to decay by
/// e⁻¹⁵ (0.5–10 s).
pub fn analyse(snake: &Snake, equilibrium: &State, set_point: &[f64]) -> Result<Stability, Error> {
    let a = linearize(snake, equilibrium, set_point)?;
    let values = eigenvalues(&a)?;
    let slowest = values[0];
    let damping_ratio = if slowest.norm() > 0.0 { -slowest.re / slowest.norm() } else { 0.0 };
    let return_time = if slowest.re < 0.0 { (15.0 / -slowest.re).clamp(0.5, 10.0) } else { 2.0 };
    let mut run = equilibrium.clone();
    for (i, q) in run.q.iter_mut().enumerate() {
        *q += if i % 2 == 0 { PERTURBATION } else { -PERTURBATION };
    }
    let mut t = 0.0;
    while t < return_time {
        snake.step(&mut run, set_point, DT)?;
        t += DT;
    }
    let return_distance = run.q.iter().zip(&equilibrium.q).fold(0.0f64, |d, (a, b)| d.max((a - b).abs()));
    Ok(Stability {
        slowest: (slowest.re, slowest.im),
        damping_ratio,
        eigenvalues: values.iter().map(|v| (v.re, v.im)).collect(),
        return_distance,
        return_time,
        return_speed: run.dq.iter().fold(0.0f64, |m, v| m.max(v.abs())),
        stable: slowest.re < STABLE_REAL_PART && return_distance <= RETURN_TOLERANCE,
    })
}

/// The largest change [`rebalance`] makes to a joint's set point \[rad\]: small enough to stay elastic.
pub const MAX_REBALANCE: f64 = 0.005;

/// The set point's correction that evens out how much of their friction cones the `pressed` feet use:
/// with the feet stuck, a small change of the joint set points moves the snake elastically and shifts
/// the tangential forces between them. The change Δ minimises Σᵢ uᵢ² + ρ‖Δ‖², uᵢ = fₜᵢ/(μ fₙᵢ), in the
/// linearisation about the equilibrium (each column by Newton's equilibrium at a set point moved by
/// 1e-4 rad), with ρ a thousandth of the sensitivities' sum of squares; at most [`MAX_REBALANCE`] per
/// joint. Returns the corrected set point, or the set point as it was where Newton finds no neighbouring
/// equilibrium.
pub fn rebalance(snake: &Snake, state: &State, set_point: &[f64], pressed: &[usize]) -> Result<Vec<f64>, Error> {
    let mu = snake.friction();
    let usage = |s: &State, sp: &[f64]| -> Result<DVector<f64>, Error> {
        let forces = snake.foot_forces(s, sp)?;
        Ok(DVector::from_iterator(
            pressed.len(),
            pressed.iter().map(|&f| forces[f].tangential / (mu * forces[f].normal.max(1e-9))),
        ))
    };
    let u0 = usage(state, set_point)?;
    let h = 1e-4;
    let mut c = DMatrix::zeros(pressed.len(), set_point.len());
    for j in 0..set_point.len() {
        let mut sp = set_point.to_vec();
        sp[j] += h;
        let mut moved = state.clone();
        if refine(snake, &mut moved, &sp)? > 1e-8 {
            return Ok(set_point.to_vec());
        }
        c.set_column(j, &((usage(&moved, &sp)? - &u0) / h));
    }
    let rho = 1e-3 * (c.transpose() * &c).trace().max(1e-12);
    let normal = c.transpose() * &c + DMatrix::identity(set_point.len(), set_point.len()) * rho;
    let delta = normal.lu().solve(&(-(c.transpose() * &u0))).unwrap_or_else(|| DVector::zeros(set_point.len()));
    let scale = (MAX_REBALANCE / delta.amax().max(1e-300)).min(1.0);
    Ok(set_point.iter().zip(delta.iter()).map(|(q, d)| q + scale * d).collect())
}

/// The smallest cone margin of the feet on a wall (1 with none).
pub fn min_cone_margin(forces: &[FootForce], friction: f64) -> f64 {
    forces.iter().filter_map(|f| f.cone_margin(friction)).fold(1.0, f64::min)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::snake::tests::one_link;

    /// The balancing is a similarity: eigenvalues unchanged, and row and column norms brought together.
    /// [[0, 1e6], [1, 0]] balances to off-diagonals of 1e3 each (within a power of two).
    #[test]
    fn balancing_evens_out_a_row_and_its_column() {
        let mut a = DMatrix::from_row_slice(2, 2, &[0.0, 1e6, 1.0, 0.0]);
        balance(&mut a);
        assert!(a[(0, 1)] <= 2e3 && a[(1, 0)] >= 5e2 && (a[(0, 1)] * a[(1, 0)] - 1e6).abs() < 1e-6, "{a}");
    }

    #[test]
    fn balancing_keeps_the_eigenvalues() {
        let a = DMatrix::from_row_slice(3, 3, &[1.0, 1e6, 0.0, 1e-6, 2.0, 1e4, 0.0, 1e-4, 3.0]);
        let mut b = a.clone();
        let d = balance(&mut b);
        let back = DMatrix::from_diagonal(&DVector::from_vec(d.clone()))
            * &b
            * DMatrix::from_diagonal(&DVector::from_vec(d.iter().map(|x| 1.0 / x).collect()));
        assert!((&back - &a).amax() < 1e-9 * a.amax(), "D B D⁻¹ = A");
        assert!(b.amax() < 1e3, "balanced: {b}");
        let (ea, eb) = (a.complex_eigenvalues(), eigenvalues(&a).unwrap());
        let mut ea: Vec<f64> = ea.iter().map(|c| c.re).collect();
        ea.sort_by(|x, y| y.total_cmp(x));
        for (x, y) in ea.iter().zip(&eb) {
            assert!((x - y.re).abs() < 1e-9, "{x} vs {}", y.re);
        }
    }

    /// One rod hung on one foot, pressed to the left wall by a 5 N load at the foot: by hand,
    /// z = (F/kₙ)^{2/3}; the tangential spring carries the weight, δₜ = mg/(kₜ √z); the rod hangs with its
    /// centre of mass below the foot. The linearisation, written out: y decouples (M has no y–x or y–φ
    /// terms; K has a y–x term, the non-symmetric ∂fₜ/∂z), so ω_y² = kₜ √z/m; x and φ share
    /// det(K − ω²M) = 0 with K = diag(1.5 kₙ √z, m g l/2), M = [[m, m l/2], [m l/2, I + m l²/4]].
    #[test]
    fn one_foot_on_a_wall_matches_the_hand_calculation() {
        let snake = one_link(0.0127);
        let (m, l, g, kn, kt): (f64, f64, f64, f64, f64) = (0.2, 0.1, snake.chain.gravity, 2.7e5, 1.3e5);
        let z = (5.0f64 / kn).powf(2.0 / 3.0);
        let mut state = State::at_rest(&snake, vec![0.0127 - z, 0.0, -std::f64::consts::FRAC_PI_2 + 0.1]);
        // Touch at the final depth, tilted; Newton then lets the weight stretch the tangential spring and
        // the rod swing below the foot.
        snake.applied_forces(&state.q.clone(), &[0.0; 3], &[], &mut state.feet).unwrap();
        let residual = refine(&snake, &mut state, &[]).unwrap();
        assert!(residual < 1e-10, "residual {residual}");
        let forces = snake.foot_forces(&state, &[]).unwrap();
        assert!((forces[0].depth - z).abs() < 1e-12, "depth {} vs {z}: {forces:?}", forces[0].depth);
        assert!((forces[0].tangential - m * g).abs() < 1e-9, "fₜ {} vs mg {}", forces[0].tangential, m * g);
        let delta_t = m * g / (kt * z.sqrt());
        assert!(delta_t > 1e-5, "the spring is stretched: {delta_t}");
        // The centre of mass hangs below the foot.
        let com = snake.chain.point(&state.q, 0, 0.05);
        assert!((com.x - state.q[0]).abs() < 1e-12, "com {com}, node {}", state.q[0]);
        let k_x = 1.5 * kn * z.sqrt();
        let k_phi = m * g * l / 2.0;
        let (mm, mx, j) = (m, m * l / 2.0, m * l * l / 12.0 + m * l * l / 4.0);
        // det([[k_x − w m, −w mx], [−w mx, k_phi − w j]]) = 0 in w = ω².
        let (qa, qb, qc) = (mm * j - mx * mx, -(k_x * j + k_phi * mm), k_x * k_phi);
        let disc = (qb * qb - 4.0 * qa * qc).sqrt();
        let mut hand = [kt * z.sqrt() / m, (-qb - disc) / (2.0 * qa), (-qb + disc) / (2.0 * qa)];
        hand.sort_by(f64::total_cmp);
        let a = linearize(&snake, &state, &[]).unwrap();
        let values = eigenvalues(&a).unwrap();
        let mut omegas: Vec<f64> = values.iter().filter(|v| v.im > 0.0).map(|v| v.im * v.im).collect();
        omegas.sort_by(f64::total_cmp);
        assert_eq!(omegas.len(), 3, "three undamped modes: {values:?}");
        for (w, h) in omegas.iter().zip(hand) {
            assert!((w - h).abs() < 1e-4 * h, "ω² {w} vs by hand {h}");
        }
        assert!(values.iter().all(|v| v.re.abs() < 1e-6 * v.im.abs().max(1.0)), "undamped: {values:?}");
    }
}
