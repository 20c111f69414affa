//! What a medium's drag is read against ([`softcontact_contact::Effect::MediumDrag`]): the speed at which
//! the sensor's zero was read, and whether free space shows the drag apart from the contact's damping.

use crate::Series;

/// The hand's mean rate [m/s] where the sensor's zero was read: over the tare windows before each tare,
/// or, with no tare in the series, over the free space before the first contact (where an instrument's
/// table is zeroed); [`softcontact_contact::Effect::MediumDrag`]'s `tare_speed`.
pub(crate) fn tare_speed(s: &Series, tare_window: f64) -> f64 {
    let first_contact = s.z.iter().position(|&z| z > 0.0).unwrap_or(s.len());
    let zeroed = |i: usize| match s.tares.is_empty() {
        true => i < first_contact,
        false => s.tares.iter().any(|&tare| (tare - tare_window..=tare).contains(&s.t[i])),
    };
    let (sum, n) = (0..s.len()).filter(|&i| zeroed(i)).fold((0.0, 0usize), |(sum, n), i| (sum + s.zdot[i], n + 1));
    if n > 0 { sum / n as f64 } else { 0.0 }
}

/// Whether free space is crossed at speeds that differ (5th to 95th percentile) by at least half the
/// record's 95th-percentile speed: a drag can show there, apart from the contact's own damping.
pub(crate) fn drag_observable(s: &Series) -> bool {
    let percentile = |v: &mut Vec<f64>, p: f64| {
        v.sort_by(f64::total_cmp);
        v.get(((v.len() - 1) as f64 * p).round() as usize).copied().unwrap_or(0.0)
    };
    let mut free: Vec<f64> = (0..s.len()).filter(|&i| s.z[i] <= 0.0).map(|i| s.zdot[i]).collect();
    if free.len() < crate::MIN_CONTACT_SAMPLES {
        return false;
    }
    let spread = percentile(&mut free, 0.95) - percentile(&mut free, 0.05);
    spread > 0.0 && spread >= 0.5 * crate::phase::p95_speed(s)
}
