//! The record cut into cells, and the two layouts of folds over them that the cross-validation judges by:
//! interleaved (each fold's complement holds both halves of the contact; what the rules that accept an
//! effect use) and contiguous in time (each fold extrapolated from the others; what tells rivals apart).
//! `crates/discrepancy/README.md` argues the choice.

use std::ops::Range;

/// The cells of a record of deformations `z`: its free space before the first contact, its contact and its
/// free space after, each in 2·`folds` contiguous parts; the contact's parts hold equal shares of the
/// in-contact samples (a record whose contact is a tenth of it, an indentation between long stretches of
/// free space, would otherwise have all of its contact in a part or two). A record with fewer in-contact
/// samples than parts is one region, cut into equal parts of time, between two empty ones.
pub(crate) fn cells(z: &[f64], folds: usize) -> Vec<Range<usize>> {
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
    let edge = |i: usize| match i {
        0 => first,
        i if i == parts => end,
        i => contact[i * contact.len() / parts],
    };
    let mut out = split(0..first);
    out.extend((0..parts).map(|i| edge(i)..edge(i + 1)));
    out.extend(split(end..n));
    out
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
        let c = cells(z, folds);
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
