//! The record cut into cells, and the two layouts of folds over them that the cross-validation judges by:
//! interleaved (each fold's complement holds both halves of the contact; what the rules that accept an
//! effect use) and contiguous in time (each fold extrapolated from the others; what tells rivals apart).
//! `crates/discrepancy/README.md` argues the choice.

use std::ops::Range;

/// The cells of a record of deformations `z` and their rates `zdot`: its free space before the first
/// contact, its contact and its free space after, each in 2·`folds` contiguous parts. The contact's parts
/// hold equal shares of the in-contact samples' weights ([`contact_weights`]): each sample counts once,
/// but a hold longer than the contact's motion counts on a logarithmic scale of time (a record whose
/// contact is a tenth of it, an indentation between long stretches of free space, would otherwise have all
/// of its contact in a part or two; a ramp and a 30-minute hold, its ramp and the hold's first minutes
/// where every relaxation shows in one part). A record with fewer in-contact samples than parts is one
/// region, cut into equal parts of time, between two empty ones.
pub(crate) fn cells(t: &[f64], z: &[f64], zdot: &[f64], folds: usize) -> Vec<Range<usize>> {
    let n = z.len();
    let parts = 2 * folds;
    let contact: Vec<usize> = (0..n).filter(|&i| z[i] > 0.0).collect();
    let split = |r: Range<usize>| -> Vec<Range<usize>> {
        let (a, len) = (r.start, r.len());
        (0..parts).map(|i| a + i * len / parts..a + (i + 1) * len / parts).collect()
    };
    if contact.len() < parts {
        return [split(0..0), split(0..n), split(n..n)].concat();
    }
    let (first, end) = (contact[0], contact[contact.len() - 1] + 1);
    // The in-contact sample at which each share of the weight is reached.
    let weights = contact_weights(t, &contact, zdot, parts);
    let total: f64 = weights.iter().sum();
    let mut reached = Vec::with_capacity(parts);
    let mut acc = 0.0;
    for (k, w) in weights.iter().enumerate() {
        acc += w;
        while reached.len() < parts - 1 && acc >= total * (reached.len() + 1) as f64 / parts as f64 {
            reached.push((k + 1).min(contact.len() - 1));
        }
    }
    // Every part holds at least one in-contact sample.
    for i in 0..reached.len() {
        let least = if i == 0 { 1 } else { reached[i - 1] + 1 };
        reached[i] = reached[i].max(least).min(contact.len() - (parts - 1 - i));
    }
    let edge = |i: usize| match i {
        0 => first,
        i if i == parts => end,
        i => contact[reached[i - 1]],
    };
    let mut out = split(0..first);
    out.extend((0..parts).map(|i| edge(i)..edge(i + 1)));
    out.extend(split(end..n));
    out
}

/// The weight of each in-contact sample (indices `contact`, times `t`) in cutting the contact into parts:
/// 1, except in a hold (a run of samples whose speed is at most a twentieth of the contact's 99.9th
/// percentile speed, where that is not zero: a ramp may be a thousandth of the contact) once it has lasted
/// as long as all the contact's motion, of L samples (at least `parts`): a sample of step Δt at the time h
/// into the hold then weighs L·Δt/h, so that the hold counts as the logarithm of its duration however
/// the instrument logged it (at a constant rate, the k-th sample past the first L weighs L/k). A
/// relaxation spreads over decades of time: equal counts put a long hold's first decades, where its
/// faster branches show, in one part.
fn contact_weights(t: &[f64], contact: &[usize], zdot: &[f64], parts: usize) -> Vec<f64> {
    let mut speeds: Vec<f64> = contact.iter().map(|&i| zdot[i].abs()).collect();
    speeds.sort_by(f64::total_cmp);
    let floor = 0.05 * speeds[(speeds.len() * 999 / 1000).min(speeds.len() - 1)];
    if floor <= 0.0 {
        // No motion in contact to set a hold against (no rate known): counts alone.
        return vec![1.0; contact.len()];
    }
    let still = |i: usize| zdot[i].abs() <= floor;
    let step = |i: usize| if i > 0 { t[i] - t[i - 1] } else { 0.0 };
    let moving: Vec<usize> = contact.iter().copied().filter(|&i| !still(i)).collect();
    let count = moving.len().max(parts) as f64;
    // How long the contact moves: a hold counts on the logarithm of its time once it has lasted as long.
    let reach = moving.iter().map(|&i| step(i)).sum::<f64>().max(f64::MIN_POSITIVE);
    let mut held: Option<f64> = None;
    let mut previous = None;
    contact
        .iter()
        .map(|&i| {
            held = match (still(i), held) {
                (true, Some(h)) if previous == Some(i.wrapping_sub(1)) => Some(h + step(i)),
                (true, _) => Some(step(i)),
                (false, _) => None,
            };
            previous = Some(i);
            // Weighed by time: a logger that slows down in a hold writes fewer, longer samples.
            held.map_or(1.0, |h| if h > reach { count * step(i) / h } else { 1.0 })
        })
        .collect()
}

/// Fold f: parts f and f + `folds` of every region. Each fold's complement then holds both halves of the
/// contact (the approach and the retract, the start of a hold and its end) and some of each free stretch,
/// so that a held-out fold is predicted by interpolation: an effect seen in one phase only (an adhesion
/// on the way out, a relaxation in the one hold) is still fitted where its fold is held out. The rules
/// that accept an effect judge by these folds; a smooth, correlated residual is what the record shows
/// between the held-out parts, not noise the fit could follow.
pub(crate) fn interleaved_folds(folds: usize) -> Vec<Vec<usize>> {
    let parts = 2 * folds;
    (0..folds).map(|f| (0..3).flat_map(|r| [r * parts + f, r * parts + f + folds]).collect()).collect()
}

/// Fold f: contact parts 2f and 2f + 1, with all the free space before the contact in the first fold and
/// all after it in the last: folds contiguous in time, each predicted by extrapolation from the others.
/// Two effects whose contributions are alike over the record differ by how they extrapolate, so rivals
/// are judged by these folds: an effect that only interpolates better than its rival is not told apart
/// from it.
pub(crate) fn contiguous_folds(folds: usize) -> Vec<Vec<usize>> {
    let parts = 2 * folds;
    (0..folds)
        .map(|f| {
            let mut fold: Vec<usize> = if f == 0 { (0..parts).collect() } else { vec![] };
            fold.extend([parts + 2 * f, parts + 2 * f + 1]);
            if f + 1 == folds {
                fold.extend(2 * parts..3 * parts);
            }
            fold
        })
        .collect()
}

#[cfg(test)]
mod fold_layout_tests {
    use super::*;

    /// Cells tile the record in order, and each layout holds every cell exactly once.
    fn assert_tiles_and_partitions(z: &[f64], folds: usize) -> Vec<std::ops::Range<usize>> {
        let c = cells(&time(z.len()), z, &vec![0.0; z.len()], folds);
        assert_eq!(c.len(), 3 * 2 * folds);
        assert_eq!(c[0].start, 0);
        assert_eq!(c.last().unwrap().end, z.len());
        for w in c.windows(2) {
            assert_eq!(w[0].end, w[1].start, "{c:?}");
        }
        for layout in [interleaved_folds(folds), contiguous_folds(folds)] {
            let mut seen: Vec<usize> = layout.concat();
            seen.sort_unstable();
            assert_eq!(seen, (0..c.len()).collect::<Vec<_>>(), "{layout:?}");
        }
        c
    }

    #[test]
    fn an_indentation_between_free_stretches_has_equal_contact_cells_and_both_halves_in_every_fold() {
        let z: Vec<f64> = (0..1000).map(|i| if (300..400).contains(&i) { 1e-6 } else { -1e-6 }).collect();
        let c = assert_tiles_and_partitions(&z, 5);
        let contact = &c[10..20];
        assert_eq!(contact[0].start, 300);
        assert_eq!(contact[9].end, 400);
        assert!(contact.iter().all(|r| r.len() == 10), "{contact:?}");
        for fold in interleaved_folds(5) {
            let parts: Vec<usize> = fold.iter().filter(|&&k| (10..20).contains(&k)).map(|k| k - 10).collect();
            assert!(parts.iter().any(|&p| p < 5) && parts.iter().any(|&p| p >= 5), "{fold:?}");
        }
        for (f, fold) in contiguous_folds(5).iter().enumerate() {
            let parts: Vec<usize> = fold.iter().filter(|&&k| (10..20).contains(&k)).copied().collect();
            assert_eq!(parts, vec![10 + 2 * f, 11 + 2 * f]);
        }
    }

    /// A ramp of 100 samples and a hold of 90 000: the hold counts as the logarithm of its duration, so
    /// that its first decades (where a fast relaxation shows) are cut over several parts instead of lying
    /// in the first part with the ramp; the parts stay in order, each holding samples.
    #[test]
    fn a_long_hold_after_a_short_ramp_is_cut_on_a_logarithmic_scale_of_its_time() {
        let n = 50 + 100 + 90_000;
        let z: Vec<f64> =
            (0..n).map(|i| if i < 50 { 0.0 } else { 1e-3 * ((i - 49) as f64 / 100.0).min(1.0) }).collect();
        let zdot: Vec<f64> = (0..n).map(|i| if (50..150).contains(&i) { 0.05 } else { 0.0 }).collect();
        let c = cells(&time(n), &z, &zdot, 5);
        let contact = &c[10..20];
        assert_eq!((contact[0].start, contact[9].end), (50, n), "{contact:?}");
        assert!(contact.iter().all(|r| !r.is_empty()), "{contact:?}");
        // Equal counts would start the second part 9 000 samples into the hold.
        let early = contact.iter().filter(|r| r.start < 150 + 900).count();
        assert!(early >= 3, "{contact:?}");
        // Each part of the hold past its first 100 samples spans about the same ratio of times.
        let ratios: Vec<f64> = contact[3..9].iter().map(|r| (r.end - 150) as f64 / (r.start - 150) as f64).collect();
        assert!(ratios.iter().all(|q| (q / ratios[0] - 1.0).abs() < 0.05), "{ratios:?}");
        // Without a rate, counts alone.
        let counted = cells(&time(n), &z, &vec![0.0; n], 5);
        assert!(counted[10..20].iter().all(|r| r.len().abs_diff(contact_len(&z) / 10) <= 1), "{counted:?}");
    }

    /// The same hold logged ever more sparsely (50 Hz for a minute, 5 Hz to ten minutes, 1 Hz after, as
    /// testing machines log a relaxation): its parts still span equal ratios of time into the hold, not
    /// equal counts of samples.
    #[test]
    fn a_hold_logged_ever_more_sparsely_is_cut_on_the_logarithm_of_its_time_not_its_samples() {
        let mut t: Vec<f64> = vec![];
        let mut now: f64 = 0.0;
        while now < 1800.0 {
            t.push(now);
            now += if now < 63.0 {
                0.02
            } else if now < 603.0 {
                0.2
            } else {
                1.0
            };
        }
        let n = t.len();
        let z: Vec<f64> = t.iter().map(|&t| if t < 1.0 { 0.0 } else { 1e-3 * ((t - 1.0) / 2.0).min(1.0) }).collect();
        let zdot: Vec<f64> = t.iter().map(|&t| if (1.0..3.0).contains(&t) { 5e-4 } else { 0.0 }).collect();
        let hold = t.iter().position(|&t| t >= 3.0).unwrap();
        let c = cells(&t, &z, &zdot, 5);
        let into = |i: usize| t[i.min(n - 1)] - t[hold];
        let ratios: Vec<f64> = c[13..19].iter().map(|r| into(r.end) / into(r.start)).collect();
        assert!(ratios.iter().all(|q| (q / ratios[0] - 1.0).abs() < 0.15), "{ratios:?} {:?}", &c[10..20]);
    }

    fn time(n: usize) -> Vec<f64> {
        (0..n).map(|i| i as f64 * 0.02).collect()
    }

    fn contact_len(z: &[f64]) -> usize {
        z.iter().filter(|&&z| z > 0.0).count()
    }

    #[test]
    fn a_record_with_hardly_any_contact_or_none_before_it_still_tiles() {
        let few: Vec<f64> = (0..97).map(|i| if i == 40 { 1e-6 } else { -1e-6 }).collect();
        let c = assert_tiles_and_partitions(&few, 5);
        assert!(c[..10].iter().chain(&c[20..]).all(|r| r.is_empty()), "{c:?}");
        let from_start: Vec<f64> = (0..500).map(|i| if i < 200 { 1e-6 } else { -1e-6 }).collect();
        let c = assert_tiles_and_partitions(&from_start, 5);
        assert!(c[..10].iter().all(|r| r.is_empty()));
        assert_eq!(c[19].end, 200);
    }
}
