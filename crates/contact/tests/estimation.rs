//! Estimation against known truth: data from hand-written laws (tests/common), never from the crate.

mod common;

use rand::rngs::SmallRng;
use rand::{Rng, SeedableRng};
use softcontact_contact::{
    DampingExponent, Exponents, FitConfig, Kind, OnsetConfig, OnsetDetector, OnsetEvent, Sample, WindowEstimator,
    estimate, estimate_contact_offset, estimate_exponent, fit, least_squares_qr, robust_least_squares,
};

const SPONGE: (f64, f64) = (0.05, 280.0);
const DICE: (f64, f64) = (0.07, 130.0);

fn rel(a: f64, b: f64) -> f64 {
    (a - b).abs() / b.abs()
}

#[test]
fn noise_free_data_gives_the_parameters_back_exactly() {
    let mut rng = SmallRng::seed_from_u64(1);
    for kind in Kind::CANDIDATES {
        for (depth, force) in [SPONGE, DICE] {
            let (k, l) = common::parameters(kind, depth, force, 0.15);
            // Where the hand outruns the released surface the force is 0, not the law's negative value:
            // those samples are not described by the law and are left out, as the estimator node does.
            let data: Vec<Sample> = common::samples(kind, k, l, &common::identification(depth, 8), 0.0, &mut rng)
                .into_iter()
                .filter(|s| s.f > 0.0)
                .collect();
            let fit = fit(kind, kind.exponents().unwrap(), &data, None, &FitConfig::default()).unwrap();
            assert!(
                rel(fit.stiffness, k) < 1e-9 && rel(fit.damping, l) < 1e-9,
                "{kind:?}: ({}, {}) vs ({k}, {l})",
                fit.stiffness,
                fit.damping
            );
            assert!((fit.fitness_mean - 1.0).abs() < 1e-9, "perfect data, perfect fitness: {}", fit.fitness_mean);
            let (kq, lq) = least_squares_qr(&data, &kind.exponents().unwrap(), None).unwrap();
            assert!(rel(kq, k) < 1e-9 && rel(lq, l) < 1e-9);
        }
    }
}

#[test]
fn noisy_identification_recovers_parameters_within_two_percent() {
    let mut rng = SmallRng::seed_from_u64(2);
    for kind in Kind::CANDIDATES {
        for (depth, force) in [SPONGE, DICE] {
            let (k, l) = common::parameters(kind, depth, force, 0.15);
            // One identification run of the force-control paper: ramp, 10 s of 1 Hz pushes, retreat; 0.2 N noise.
            let data = common::samples(kind, k, l, &common::identification(depth, 10), 0.2, &mut rng);
            let est = estimate(&data, &[None; 3], &FitConfig::default()).unwrap();
            let fit = est.fit(kind).unwrap();
            assert!(rel(fit.stiffness, k) < 0.02, "{kind:?} k {} vs {k}", fit.stiffness);
            assert!(rel(fit.damping, l) < 0.02, "{kind:?} λ {} vs {l}", fit.damping);
            assert!(!fit.damping_held && !fit.stiffness_held);
            assert_eq!(est.selected, kind, "fitness {:?}", est.fits.iter().map(|f| f.fitness_mean).collect::<Vec<_>>());
        }
    }
}

#[test]
fn the_right_kind_is_chosen_in_random_noisy_cases() {
    let mut rng = SmallRng::seed_from_u64(3);
    let cases = 200;
    let mut right = 0;
    let mut wrong = Vec::new();
    for _ in 0..cases {
        let kind = Kind::CANDIDATES[rng.random_range(0..3)];
        let depth = rng.random_range(0.03..0.07);
        let force = rng.random_range(80.0..300.0);
        let ratio = rng.random_range(0.05..0.25);
        let (k, l) = common::parameters(kind, depth, force, ratio);
        let data = common::samples(kind, k, l, &common::identification(depth, 10), 0.2, &mut rng);
        let est = estimate(&data, &[None; 3], &FitConfig::default()).unwrap();
        if est.selected == kind {
            right += 1;
        } else {
            wrong.push((kind, est.selected, depth, force, ratio));
        }
    }
    eprintln!(
        "kind chosen right in {right}/{cases} cases; wrong (truth, chosen, depth, force, damping ratio): {wrong:?}"
    );
    assert!(right as f64 >= 0.95 * cases as f64, "{right}/{cases} right; wrong: {wrong:?}");
}

/// The running moments give, at every checkpoint, what a fresh QR fit of the window's samples gives.
#[test]
fn sliding_updates_agree_with_batch_refits_over_100k_samples() {
    let mut rng = SmallRng::seed_from_u64(4);
    let mut window = WindowEstimator::new(1200, FitConfig::default()).unwrap();
    let (k, l) = common::parameters(Kind::AzadFeatherstone, 0.05, 280.0, 0.15);
    let mut stored: std::collections::VecDeque<Sample> = Default::default();
    let mut worst: f64 = 0.0;
    for i in 0..100_000 {
        // Pushes of changing depth and pace, always in contact, 0.2 N noise.
        let t = i as f64 * 0.01;
        let depth = 0.03 + 0.015 * (0.013 * t).sin();
        let w = 2.0 * std::f64::consts::PI * (0.7 + 0.3 * (0.021 * t).cos());
        let (z, zd) = (0.002 + depth * (0.5 + 0.5 * (w * t).sin()), depth * 0.5 * w * (w * t).cos());
        let f = common::closed_form(Kind::AzadFeatherstone, k, l, z, zd) + rng.random_range(-0.35..0.35);
        let s = Sample { z, zdot: zd, f };
        window.push(s).unwrap();
        stored.push_back(s);
        if stored.len() > 1200 {
            stored.pop_front();
        }
        if i % 997 == 996 || i == 99_999 {
            let batch: Vec<Sample> = stored.iter().copied().collect();
            assert!(window.samples().copied().eq(batch.iter().copied()), "window content at {i}");
            for kind in Kind::CANDIDATES {
                let (ko, lo) = window.current(kind).unwrap();
                let (kb, lb) = least_squares_qr(&batch, &kind.exponents().unwrap(), None).unwrap();
                worst = worst.max(rel(ko, kb)).max((lo - lb).abs() / lb.abs().max(1e-3 * kb.abs()));
            }
        }
    }
    eprintln!("sliding vs batch QR: largest relative difference {worst:e}");
    assert!(worst < 1e-9, "largest relative difference {worst:e}");
}

#[test]
fn a_long_hold_keeps_damping_at_its_prior_and_says_so() {
    let mut rng = SmallRng::seed_from_u64(5);
    let (k, l) = common::parameters(Kind::AzadFeatherstone, 0.05, 280.0, 0.15);
    let mut window = WindowEstimator::new(1200, FitConfig::default()).unwrap();
    // Identification first: the window learns both parameters.
    for s in common::samples(Kind::AzadFeatherstone, k, l, &common::identification(0.05, 12), 0.2, &mut rng) {
        window.push(s).unwrap();
    }
    let learned = window.refit().unwrap();
    let af = learned.fit(Kind::AzadFeatherstone).unwrap().clone();
    assert!(!af.damping_held && rel(af.damping, l) < 0.03, "λ {} vs {l}", af.damping);
    // Then 12 s of holds at three depths: ż ≈ 0, nothing to learn about λ.
    let holds: Vec<(f64, f64)> = (0..1200).map(|i| (0.02 + 0.01 * (i / 400) as f64, 0.0)).collect();
    for s in common::samples(Kind::AzadFeatherstone, k, l, &holds, 0.2, &mut rng) {
        window.push(s).unwrap();
    }
    let held = window.refit().unwrap();
    let af_hold = held.fit(Kind::AzadFeatherstone).unwrap();
    assert!(af_hold.damping_held, "λ must be flagged as not excited");
    assert_eq!(af_hold.damping, af.damping, "λ stays at its prior");
    assert!(rel(af_hold.stiffness, k) < 0.01, "k is still learned: {} vs {k}", af_hold.stiffness);
}

#[test]
fn the_stiffness_exponent_is_estimated() {
    let mut rng = SmallRng::seed_from_u64(6);
    // A law none of the named kinds has: a = 1.3, b = 0.5.
    let (a, k, l) = (1.3, 140.0 / 0.06f64.powf(1.3), 300.0);
    let data: Vec<Sample> = common::identification(0.06, 10)
        .into_iter()
        .filter(|(z, _)| *z > 0.0)
        .map(|(z, zd)| Sample { z, zdot: zd, f: k * z.powf(a) + l * z.sqrt() * zd + rng.random_range(-0.35..0.35) })
        .collect();
    let fit = estimate_exponent(&data, DampingExponent::Fixed(0.5), 1.0, (0.8, 2.5), &FitConfig::default()).unwrap();
    assert!((fit.exponents.a - a).abs() < 0.01, "a = {}", fit.exponents.a);
    assert!(rel(fit.stiffness, k) < 0.05 && rel(fit.damping, l) < 0.05, "k {} λ {}", fit.stiffness, fit.damping);
    let named = estimate(&data, &[None; 3], &FitConfig::default()).unwrap();
    assert!(
        fit.fitness_mean > named.selected_fit().fitness_mean,
        "the estimated exponent fits better than any named law"
    );
}

#[test]
fn the_contact_offset_is_estimated_jointly_with_the_model() {
    let mut rng = SmallRng::seed_from_u64(7);
    let (k, l) = common::parameters(Kind::AzadFeatherstone, 0.05, 280.0, 0.15);
    let traj = common::identification(0.05, 10);
    // The surface really is at true z = 0; a 1 N threshold on this sponge fires later, at δ0 deep.
    let delta0 = (1.0 / k).powf(2.0 / 3.0);
    let mut onset = OnsetDetector::new(OnsetConfig::default()).unwrap();
    let mut d = None;
    let noisy: Vec<(f64, f64, f64)> = traj
        .iter()
        .map(|&(z, zd)| (z, zd, common::closed_form(Kind::AzadFeatherstone, k, l, z, zd) + rng.random_range(-0.3..0.3)))
        .collect();
    for &(z, _, f) in &noisy {
        if let Some(OnsetEvent::Contact { position }) = onset.update(z, f).unwrap() {
            d = Some(position);
            break;
        }
    }
    let d = d.expect("contact detected");
    assert!(d > 0.5 * delta0, "the threshold misplaces the surface by {d} m");
    // Samples as the estimator sees them: z from the onset position.
    let seen: Vec<Sample> =
        noisy.iter().map(|&(z, zd, f)| Sample { z: z - d, zdot: zd, f }).filter(|s| s.z > -0.01).collect();
    let (delta, fit) = estimate_contact_offset(
        &seen,
        Exponents { a: 1.5, b: 0.5, c: 1.0 },
        (-0.02, 0.02),
        None,
        &FitConfig::default(),
    )
    .unwrap();
    assert!((d + delta).abs() < 3e-4, "surface found at {} m (truth 0, onset said {d})", d + delta);
    assert!(rel(fit.stiffness, k) < 0.03, "k {} vs {k}", fit.stiffness);
}

#[test]
fn robust_fitting_ignores_outliers() {
    let mut rng = SmallRng::seed_from_u64(8);
    let (k, l) = common::parameters(Kind::KelvinVoigt, 0.07, 130.0, 0.15);
    let mut data = common::samples(Kind::KelvinVoigt, k, l, &common::identification(0.07, 10), 0.2, &mut rng);
    for s in data.iter_mut().step_by(20) {
        s.f += 40.0; // 5 % of readings hit by a knock on the sensor
    }
    let e = Kind::KelvinVoigt.exponents().unwrap();
    let (kp, _) = least_squares_qr(&data, &e, None).unwrap();
    let (kr, lr) = robust_least_squares(&data, &e, 30).unwrap();
    assert!(rel(kp, k) > 0.02, "plain least squares is pulled by the outliers ({kp} vs {k})");
    assert!(rel(kr, k) < 0.01 && rel(lr, l) < 0.05, "robust: k {kr} vs {k}, λ {lr} vs {l}");
}

#[test]
fn onset_needs_three_readings_and_reports_the_first() {
    let mut onset = OnsetDetector::new(OnsetConfig::default()).unwrap();
    // A single spike does not count.
    assert_eq!(onset.update(0.000, 0.2).unwrap(), None);
    assert_eq!(onset.update(0.001, 5.0).unwrap(), None);
    assert_eq!(onset.update(0.002, 0.3).unwrap(), None);
    assert!(!onset.in_contact());
    // Three in a row: contact, at the first of the three.
    assert_eq!(onset.update(0.003, 1.2).unwrap(), None);
    assert_eq!(onset.update(0.004, 1.6).unwrap(), None);
    assert_eq!(onset.update(0.005, 2.0).unwrap(), Some(OnsetEvent::Contact { position: 0.003 }));
    assert!(onset.in_contact());
    assert!(onset.update(f64::NAN, 1.0).is_err(), "NaN refused");
    // Release after three readings below half the threshold.
    assert_eq!(onset.update(0.004, 0.2).unwrap(), None);
    assert_eq!(onset.update(0.003, 0.1).unwrap(), None);
    assert_eq!(onset.update(0.002, 0.0).unwrap(), Some(OnsetEvent::Release));
    assert!(OnsetDetector::new(OnsetConfig { threshold: 0.0, confirm: 3 }).is_err());
}

#[test]
fn bad_samples_are_refused_and_change_nothing() {
    let mut window = WindowEstimator::new(100, FitConfig::default()).unwrap();
    window.push(Sample { z: 0.01, zdot: 0.0, f: 10.0 }).unwrap();
    assert!(window.push(Sample { z: f64::NAN, zdot: 0.0, f: 1.0 }).is_err());
    assert!(window.push(Sample { z: 0.01, zdot: f64::INFINITY, f: 1.0 }).is_err());
    assert_eq!(window.len(), 1);
    assert!(window.refit().is_err(), "too few samples is an error, not a guess");
    assert!(WindowEstimator::new(5, FitConfig::default()).is_err());
}

#[test]
fn the_stiffness_exponent_is_estimated_when_damping_follows_it() {
    let mut rng = SmallRng::seed_from_u64(9);
    // Hunt-Crossley-like family with a = b = 1.4.
    let (a, k, l) = (1.4, 200.0 / 0.05f64.powf(1.4), 2500.0);
    let data: Vec<Sample> = common::identification(0.05, 10)
        .into_iter()
        .filter(|(z, _)| *z > 0.0)
        .map(|(z, zd)| Sample { z, zdot: zd, f: k * z.powf(a) + l * z.powf(a) * zd + rng.random_range(-0.35..0.35) })
        .collect();
    let fit = estimate_exponent(&data, DampingExponent::FollowsStiffness(0.0), 1.0, (0.8, 2.5), &FitConfig::default())
        .unwrap();
    assert!((fit.exponents.a - a).abs() < 0.01 && fit.exponents.b == fit.exponents.a, "{:?}", fit.exponents);
    assert!(rel(fit.stiffness, k) < 0.05 && rel(fit.damping, l) < 0.05, "k {} λ {}", fit.stiffness, fit.damping);
}

#[test]
fn folds_that_are_holds_score_sensibly_about_the_mean_force_of_all_the_data() {
    // Pushes, then a long hold at one depth (as a recording of a control run has): the hold folds have
    // next to no spread of their own, but every kind must still score sensibly, the true one best.
    let mut rng = SmallRng::seed_from_u64(9);
    for kind in Kind::CANDIDATES {
        let (k, l) = common::parameters(kind, 0.05, 280.0, 0.15);
        let mut traj = common::identification(0.05, 6);
        traj.extend((0..2400).map(|_| (0.03, 0.0)));
        let samples = common::samples(kind, k, l, &traj, 0.2, &mut rng);
        let overall = FitConfig { score_about_overall_mean: true, ..Default::default() };
        let mut window = WindowEstimator::new(traj.len(), overall).unwrap();
        for s in &samples {
            window.push(*s).unwrap();
        }
        let e = window.refit().unwrap();
        let truth = e.fit(kind).unwrap();
        assert!(truth.fitness_mean > 0.9, "{kind:?}: fitness {} with hold folds", truth.fitness_mean);
        assert_eq!(e.selected, kind);
        // Scored about each fold's own mean, the hold folds drag the true kind's score down.
        let mut own = WindowEstimator::new(traj.len(), FitConfig::default()).unwrap();
        for s in &samples {
            own.push(*s).unwrap();
        }
        let own_score = own.refit().unwrap().fit(kind).unwrap().fitness_mean;
        assert!(own_score < truth.fitness_mean, "{kind:?}: own-mean {own_score} vs {}", truth.fitness_mean);
    }
}
