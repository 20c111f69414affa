//! Where the node's counts → SI calibration comes from: the box's own settings page (`netftapi2.xml`
//! over HTTP: counts per unit, units, calibrated ranges, RDT rate), or the parameters alone when the
//! page is not read (`http_port` 0). A calibration parameter that is set and disagrees with the box
//! stops the node unless `calibration_override` says the parameters win: a calibration copied by hand
//! from another box, or from this box before it was reconfigured, scales every force the arm presses
//! with, and judges saturation against the wrong ranges.

use std::net::SocketAddr;
use std::time::{Duration, Instant};

use softcontact_wire::netft_xml::{self, BoxSettings};
use softcontact_wire::rdt::Calibration;

use super::Params;

/// Reads the box's settings page once, within `timeout`.
pub fn fetch_settings(http: SocketAddr, timeout: Duration) -> Result<BoxSettings, FetchError> {
    let url = format!("http://{http}{}", netft_xml::PATH);
    // No redirects: the calibration comes from the box that streams, or from nowhere.
    let config = ureq::Agent::config_builder().timeout_global(Some(timeout)).max_redirects(0).build();
    let agent = ureq::Agent::new_with_config(config);
    let mut response = agent.get(&url).call().map_err(|e| FetchError::NoPage(format!("{url}: {e}")))?;
    if response.status().is_redirection() {
        return Err(FetchError::Refused(format!("{url}: a redirect ({}), not the box's page", response.status())));
    }
    let page = response
        .body_mut()
        .with_config()
        .limit(netft_xml::MAX_PAGE as u64)
        .read_to_string()
        .map_err(|e| FetchError::NoPage(format!("{url}: {e}")))?;
    BoxSettings::parse(&page).map_err(|e| FetchError::Refused(format!("{url}: {e}")))
}

/// Why no settings were read: no page came (the box may still be booting: asked again), or a page came
/// and is not a box's settings (refused at once).
#[derive(Debug, Clone, PartialEq)]
pub enum FetchError {
    NoPage(String),
    Refused(String),
}

impl std::fmt::Display for FetchError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            FetchError::NoPage(e) => write!(f, "no settings page: {e}"),
            FetchError::Refused(e) => write!(f, "settings page refused: {e}"),
        }
    }
}

/// Asks the box for its settings page until it answers or `patience` has passed (a box that is still
/// booting answers a few seconds after power-up), while `go_on` holds. The last error if it never does.
pub fn fetch_settings_patiently(
    http: SocketAddr,
    patience: Duration,
    mut go_on: impl FnMut() -> bool,
) -> Result<BoxSettings, FetchError> {
    let give_up = Instant::now() + patience;
    loop {
        let left = give_up.saturating_duration_since(Instant::now());
        match fetch_settings(http, left.clamp(Duration::from_millis(100), Duration::from_secs(2))) {
            Ok(s) => return Ok(s),
            Err(e @ FetchError::Refused(_)) => return Err(e),
            Err(e) if Instant::now() >= give_up || !go_on() => return Err(e),
            Err(_) => std::thread::sleep(Duration::from_millis(200).min(left)),
        }
    }
}

/// The calibration the node runs with, and a line saying where it came from. `from_box` is the box's
/// page when it was read (`http_port` not 0).
pub fn resolve(p: &Params, from_box: Option<&BoxSettings>) -> Result<(Calibration, String), String> {
    let set = SetByHand::of(p);
    let Some(page) = from_box else {
        let (Some(cpf), Some(cpt), Some(fu), Some(tu), Some(ranges)) =
            (set.cpf, set.cpt, set.force_unit, set.torque_unit, set.ranges)
        else {
            return Err("http_port is 0 (the box's netftapi2.xml is not read), so counts_per_force, \
                        counts_per_torque, force_unit, torque_unit and ranges must all be set"
                .into());
        };
        let page = BoxSettings {
            product: String::new(),
            calibration_serial: String::new(),
            counts_per_force: cpf,
            counts_per_torque: cpt,
            force_unit: fu.into(),
            torque_unit: tu.into(),
            ranges,
            rdt_rate: None,
            rdt_buffer: None,
        };
        let calibration = page.calibration().map_err(|e| e.to_string())?;
        return Ok((calibration, format!("calibration from the parameters: {}", describe(&page))));
    };
    let boxed = page.calibration().map_err(|e| e.to_string())?;
    let Some(rate) = page.rdt_rate else {
        return Err("the box's page gives no RDT rate (comrdtrate): its stream cannot be checked".into());
    };
    if (rate as f64 - p.rate).abs() > 0.01 * p.rate {
        let fix = if (100..=7000).contains(&rate) { format!(", or -p rate:={rate}") } else { String::new() };
        return Err(format!(
            "the box streams {rate} Hz (comrdtrate) and rate is {} Hz: set the box's RDT rate on its \
             Communications page to {}{fix}",
            p.rate, p.rate
        ));
    }
    // Each parameter that is set against the box's value: equal, or a disagreement.
    let mut differ = Vec::new();
    let mut used = page.clone();
    let same = |a: f64, b: f64| (a - b).abs() <= 1e-9 * a.abs().max(b.abs());
    if let Some(v) = set.cpf.filter(|v| !same(*v, page.counts_per_force)) {
        differ.push(format!("counts_per_force {v} (the box: cfgcpf {})", page.counts_per_force));
        used.counts_per_force = v;
    }
    if let Some(v) = set.cpt.filter(|v| !same(*v, page.counts_per_torque)) {
        differ.push(format!("counts_per_torque {v} (the box: cfgcpt {})", page.counts_per_torque));
        used.counts_per_torque = v;
    }
    let unit_of = |force: &str, torque: &str| {
        Calibration::from_settings(1.0, 1.0, force, torque, [0.0; 6]).map(|c| (c.force_unit, c.torque_unit))
    };
    let box_units = unit_of(&page.force_unit, &page.torque_unit).map_err(|e| e.to_string())?;
    if let Some(u) = set.force_unit {
        let factor = unit_of(u, &page.torque_unit).map_err(|e| format!("force_unit: {e}"))?.0;
        if !same(factor, box_units.0) {
            differ.push(format!("force_unit {u} (the box: scfgfu {})", page.force_unit));
            used.force_unit = u.into();
        }
    }
    if let Some(u) = set.torque_unit {
        let factor = unit_of(&page.force_unit, u).map_err(|e| format!("torque_unit: {e}"))?.1;
        if !same(factor, box_units.1) {
            differ.push(format!("torque_unit {u} (the box: scfgtu {})", page.torque_unit));
            used.torque_unit = u.into();
        }
    }
    if let Some(r) = set.ranges.filter(|r| !r.iter().zip(&page.ranges).all(|(a, b)| same(*a, *b))) {
        differ.push(format!("ranges {r:?} (the box: cfgmr {:?})", page.ranges));
        used.ranges = r;
    }
    let product = if page.product.is_empty() { "the box".to_string() } else { printable(&page.product) };
    if differ.is_empty() {
        return Ok((boxed, format!("calibration from {product}: {}", describe(page))));
    }
    if !p.calibration_override {
        return Err(format!(
            "set and different from {product}'s netftapi2.xml: {}. The box's own calibration is what its \
             counts mean: unset these parameters, or set calibration_override:=true to use them anyway",
            differ.join("; ")
        ));
    }
    let calibration = used.calibration().map_err(|e| e.to_string())?;
    Ok((
        calibration,
        format!(
            "calibration_override: the parameters, not {product}'s page, for {}; running with {}",
            differ.join("; "),
            describe(&used)
        ),
    ))
}

/// A name from the box as a log line may show it: no control characters, at most 80 characters.
fn printable(name: &str) -> String {
    name.chars().filter(|c| !c.is_control()).take(80).collect()
}

fn describe(s: &BoxSettings) -> String {
    format!(
        "{} counts/{}, {} counts/{}, ranges {:?}{}",
        s.counts_per_force,
        s.force_unit,
        s.counts_per_torque,
        s.torque_unit,
        s.ranges,
        if s.calibration_serial.is_empty() {
            String::new()
        } else {
            format!(" (calibration {})", printable(&s.calibration_serial))
        }
    )
}

/// The calibration parameters a user set (0, "" and [] mean: take it from the box).
struct SetByHand<'a> {
    cpf: Option<f64>,
    cpt: Option<f64>,
    force_unit: Option<&'a str>,
    torque_unit: Option<&'a str>,
    ranges: Option<[f64; 6]>,
}

impl<'a> SetByHand<'a> {
    fn of(p: &'a Params) -> Self {
        Self {
            cpf: (p.counts_per_force != 0.0).then_some(p.counts_per_force),
            cpt: (p.counts_per_torque != 0.0).then_some(p.counts_per_torque),
            force_unit: (!p.force_unit.is_empty()).then_some(p.force_unit.as_str()),
            torque_unit: (!p.torque_unit.is_empty()).then_some(p.torque_unit.as_str()),
            ranges: <[f64; 6]>::try_from(p.ranges.as_slice()).ok(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn nano17() -> BoxSettings {
        BoxSettings { rdt_rate: Some(1000), ..BoxSettings::nano17_si_25_025() }
    }

    #[test]
    fn unset_parameters_take_the_boxs_calibration_and_ranges() {
        let (c, said) = resolve(&Params::default(), Some(&nano17())).unwrap();
        assert_eq!(c.range, [25.0, 25.0, 35.0, 0.25, 0.25, 0.25]);
        assert_eq!(c.to_si(&[0, 0, 1_000_000, 1000, 0, 0]), [0.0, 0.0, 1.0, 1e-3, 0.0, 0.0]);
        assert!(said.contains("Nano17") && said.contains("FT-SIM-17"), "{said}");
    }

    #[test]
    fn parameters_equal_to_the_box_are_accepted_and_units_compare_by_meaning() {
        let p = Params {
            counts_per_force: 1e6,
            counts_per_torque: 1e3,
            force_unit: "N".into(),
            torque_unit: "N-mm".into(),
            ranges: vec![25.0, 25.0, 35.0, 250.0, 250.0, 250.0],
            ..Params::default()
        };
        assert_eq!(resolve(&p, Some(&nano17())).unwrap().0, nano17().calibration().unwrap());
    }

    #[test]
    fn a_hand_copied_calibration_that_differs_from_the_box_stops_the_node_unless_overridden() {
        // The Gamma's calibration copied onto a Nano17's box: 1 000 000 counts per N·m, not per N·mm.
        let p =
            Params { counts_per_torque: 1e6, ranges: vec![130.0, 130.0, 400.0, 10.0, 10.0, 10.0], ..Params::default() };
        let e = resolve(&p, Some(&nano17())).unwrap_err();
        assert!(e.contains("counts_per_torque 1000000 (the box: cfgcpt 1000)") && e.contains("cfgmr"), "{e}");
        assert!(e.contains("calibration_override"), "{e}");
        let over = Params { calibration_override: true, ..p };
        let (c, said) = resolve(&over, Some(&nano17())).unwrap();
        assert_eq!(c.counts_per_torque, 1e6);
        assert_eq!(c.range[0], 130.0);
        assert!(said.starts_with("calibration_override"), "{said}");
    }

    #[test]
    fn a_box_streaming_at_another_rate_than_the_node_expects_stops_it() {
        let fast = BoxSettings { rdt_rate: Some(7000), ..nano17() };
        let e = resolve(&Params::default(), Some(&fast)).unwrap_err();
        assert!(e.contains("7000 Hz") && e.contains("rate"), "{e}");
    }

    #[test]
    fn a_page_without_a_rate_or_a_calibration_beyond_a_records_counts_stops_the_node() {
        let no_rate = BoxSettings { rdt_rate: None, ..nano17() };
        assert!(resolve(&Params::default(), Some(&no_rate)).unwrap_err().contains("comrdtrate"));
        // Parameters alone, legal one by one, but 130 N at 10⁸ counts per N is beyond an i32 count.
        let p = Params {
            counts_per_force: 1e8,
            counts_per_torque: 1e6,
            force_unit: "N".into(),
            torque_unit: "Nm".into(),
            ranges: vec![130.0, 130.0, 400.0, 10.0, 10.0, 10.0],
            http_port: 0,
            ..Params::default()
        };
        assert!(resolve(&p, None).unwrap_err().contains("Fx's range 130"));
        let over = Params { calibration_override: true, http_port: 49180, ..p };
        assert!(resolve(&over, Some(&BoxSettings::gamma_si_130_10())).unwrap_err().contains("Fx's range 130"));
    }

    #[test]
    fn a_box_name_cannot_write_log_lines() {
        let name = format!("Gamma\n\x1b[2Jft_sensor: calibration from {}", "x".repeat(500));
        let page = BoxSettings { product: name, ..nano17() };
        let said = resolve(&Params::default(), Some(&page)).unwrap().1;
        assert!(!said.contains('\n') && !said.contains('\x1b') && said.len() < 400, "{said}");
    }

    #[test]
    fn without_the_page_every_calibration_parameter_is_needed() {
        let e = resolve(&Params { counts_per_force: 1e6, ..Params::default() }, None).unwrap_err();
        assert!(e.contains("http_port is 0") && e.contains("ranges"), "{e}");
        let p = Params {
            counts_per_force: 1e6,
            counts_per_torque: 1e6,
            force_unit: "N".into(),
            torque_unit: "Nm".into(),
            ranges: vec![130.0, 130.0, 400.0, 10.0, 10.0, 10.0],
            http_port: 0,
            ..Params::default()
        };
        let (c, said) = resolve(&p, None).unwrap();
        assert_eq!(c, Calibration::gamma_si_130_10());
        assert!(said.contains("from the parameters") && !said.contains("FT-SIM"), "{said}");
    }
}
