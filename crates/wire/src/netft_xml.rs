//! The Net F/T box's settings page, `GET /netftapi2.xml` over HTTP (docs/protocols/netft-rdt.md, §5 and
//! §9): one root element (`netft` on the boxes seen) whose children are one setting each, arrays
//! separated by `;`. The product reads the active calibration from it — counts per force and torque
//! unit (`cfgcpf`, `cfgcpt`), the configured units (`scfgfu`, `scfgtu`) and the calibrated range of each
//! axis in those units (`cfgmr`) — and the RDT rate and buffer size (`comrdtrate`, `comrdtbsiz`); the
//! simulated box serves the same page. Anything else on the page is skipped.

use crate::WireError;
use crate::rdt::Calibration;
use quick_xml::events::Event;

/// The page's path on the box's web server.
pub const PATH: &str = "/netftapi2.xml";
/// The largest page read (a box's is about 2 kB): a larger answer is not a box's settings.
pub const MAX_PAGE: usize = 64 * 1024;
/// Counts per unit an ATI calibration can have (the node's parameters take the same range).
pub const COUNTS_PER_UNIT: std::ops::RangeInclusive<f64> = 1.0..=1e9;
/// The largest calibrated range taken, in the configured unit.
pub const RANGE_AT_MOST: f64 = 1e6;
/// The root element of the page.
pub const ROOT: &str = "netft";

/// What the product reads of `netftapi2.xml`, in the box's configured units.
#[derive(Debug, Clone, PartialEq)]
pub struct BoxSettings {
    /// `prodname` (empty when the page has none).
    pub product: String,
    /// `cfgcalsn`: the serial number of the active calibration (empty when the page has none).
    pub calibration_serial: String,
    /// `cfgcpf`, `cfgcpt`: counts per configured force and torque unit.
    pub counts_per_force: f64,
    pub counts_per_torque: f64,
    /// `scfgfu`, `scfgtu`: the configured units, as the box spells them.
    pub force_unit: String,
    pub torque_unit: String,
    /// `cfgmr`: the calibrated range of Fx Fy Fz Tx Ty Tz, in the configured units.
    pub ranges: [f64; 6],
    /// `comrdtrate`: RDT records per second.
    pub rdt_rate: Option<u32>,
    /// `comrdtbsiz`: records per datagram in buffered mode.
    pub rdt_buffer: Option<u32>,
}

fn bad(what: impl Into<String>) -> WireError {
    WireError::Settings(what.into())
}

fn number(tag: &str, text: &str, (lo, hi): (f64, f64)) -> Result<f64, WireError> {
    text.trim()
        .parse::<f64>()
        .ok()
        .filter(|v| v.is_finite() && *v >= lo && *v <= hi && *v > 0.0)
        .ok_or_else(|| bad(format!("<{tag}> is {text:?}, not a number in ({lo}, {hi}]")))
}

fn count(tag: &str, text: &str) -> Result<u32, WireError> {
    text.trim().parse::<u32>().map_err(|_| bad(format!("<{tag}> is {text:?}, not a whole number")))
}

impl BoxSettings {
    /// The settings of a page; an error names the setting that is missing or malformed.
    pub fn parse(page: &str) -> Result<Self, WireError> {
        if page.len() > MAX_PAGE {
            return Err(bad(format!("the page has {} bytes; a box's has a few thousand", page.len())));
        }
        const WANTED: [&str; 9] =
            ["prodname", "cfgcalsn", "cfgcpf", "cfgcpt", "scfgfu", "scfgtu", "cfgmr", "comrdtrate", "comrdtbsiz"];
        let mut values: [Option<String>; 9] = Default::default();
        let mut reader = quick_xml::Reader::from_str(page);
        let (mut depth, mut current, mut root_seen) = (0usize, None::<usize>, false);
        // A setting given twice is not one value: refused, never joined or chosen between.
        let open = |values: &mut [Option<String>; 9], name: &[u8]| -> Result<Option<usize>, WireError> {
            match WANTED.iter().position(|w| name == w.as_bytes()) {
                Some(i) if values[i].is_some() => Err(bad(format!("<{}> appears twice", WANTED[i]))),
                Some(i) => {
                    values[i] = Some(String::new());
                    Ok(Some(i))
                }
                None => Ok(None),
            }
        };
        loop {
            match reader.read_event().map_err(|e| bad(format!("not XML: {e}")))? {
                Event::Start(e) => {
                    depth += 1;
                    if depth == 1 {
                        if root_seen {
                            return Err(bad("a second root element"));
                        }
                        if e.name().as_ref() != ROOT.as_bytes() {
                            let name = String::from_utf8_lossy(e.name().as_ref()).into_owned();
                            return Err(bad(format!("the root is <{name}>, not <{ROOT}>: not a box's page")));
                        }
                        root_seen = true;
                    }
                    current = if depth == 2 { open(&mut values, e.name().as_ref())? } else { None };
                }
                Event::End(_) => {
                    depth = depth.saturating_sub(1);
                    current = None;
                }
                Event::Empty(e) if depth == 1 => {
                    open(&mut values, e.name().as_ref())?;
                }
                Event::Empty(_) if depth == 0 => return Err(bad("a second root element")),
                Event::Text(t) => {
                    if let Some(i) = current {
                        let text = t.decode().map_err(|e| bad(format!("<{}>: {e}", WANTED[i])))?;
                        values[i].get_or_insert_with(String::new).push_str(&text);
                    }
                }
                Event::GeneralRef(r) => {
                    if let Some(i) = current {
                        let name = r.decode().map_err(|e| bad(format!("<{}>: {e}", WANTED[i])))?;
                        let resolved = quick_xml::escape::resolve_predefined_entity(&name).unwrap_or("?");
                        values[i].get_or_insert_with(String::new).push_str(resolved);
                    }
                }
                Event::Eof if depth > 0 => return Err(bad("not XML: the page ends inside an element")),
                Event::Eof => break,
                _ => {}
            }
        }
        if !root_seen {
            return Err(bad("no root element"));
        }
        let get = |i: usize| -> Result<&str, WireError> {
            values[i].as_deref().ok_or_else(|| bad(format!("no <{}> on the page", WANTED[i])))
        };
        let ranges_text = get(6)?;
        let parts: Vec<&str> = ranges_text.split([';', ',', ' ']).map(str::trim).filter(|s| !s.is_empty()).collect();
        if parts.len() != 6 {
            return Err(bad(format!("<cfgmr> is {ranges_text:?}: six ranges expected")));
        }
        let mut ranges = [0.0; 6];
        for (r, p) in ranges.iter_mut().zip(&parts) {
            *r = number("cfgmr", p, (0.0, RANGE_AT_MOST))?;
        }
        let counts = (*COUNTS_PER_UNIT.start(), *COUNTS_PER_UNIT.end());
        Ok(Self {
            product: values[0].as_deref().unwrap_or_default().trim().to_string(),
            calibration_serial: values[1].as_deref().unwrap_or_default().trim().to_string(),
            counts_per_force: number("cfgcpf", get(2)?, counts)?,
            counts_per_torque: number("cfgcpt", get(3)?, counts)?,
            force_unit: get(4)?.trim().to_string(),
            torque_unit: get(5)?.trim().to_string(),
            ranges,
            rdt_rate: values[7].as_deref().map(|t| count("comrdtrate", t)).transpose()?,
            rdt_buffer: values[8].as_deref().map(|t| count("comrdtbsiz", t)).transpose()?,
        })
    }

    /// Counts → SI as this page configures it, the ranges converted to N and N·m. Refused where a
    /// range is more counts than a record holds: a reading at the range could then never be seen as one.
    pub fn calibration(&self) -> Result<Calibration, WireError> {
        let units = Calibration::from_settings(
            self.counts_per_force,
            self.counts_per_torque,
            &self.force_unit,
            &self.torque_unit,
            [0.0; 6],
        )?;
        let range = std::array::from_fn(|i| self.ranges[i] * if i < 3 { units.force_unit } else { units.torque_unit });
        for (i, axis) in ["Fx", "Fy", "Fz", "Tx", "Ty", "Tz"].iter().enumerate() {
            let per = if i < 3 { self.counts_per_force } else { self.counts_per_torque };
            if self.ranges[i] * per >= i32::MAX as f64 || self.ranges[i].is_nan() {
                return Err(WireError::Unit(format!(
                    "{axis}'s range {} × {per} counts per unit is beyond a record's {} counts",
                    self.ranges[i],
                    i32::MAX
                )));
            }
        }
        Ok(Calibration { range, ..units })
    }

    /// The page a box with these settings serves (the settings the product reads, in a box's layout).
    pub fn to_xml(&self) -> String {
        let esc = |s: &str| quick_xml::escape::escape(s).into_owned();
        let ranges = self.ranges.map(|r| r.to_string()).join(";");
        let mut page = format!(
            "<?xml version=\"1.0\"?><netft>\n<runstat>0x00000000</runstat>\n<prodname>{}</prodname>\n\
             <cfgcalsn>{}</cfgcalsn>\n<scfgfu>{}</scfgfu><scfgtu>{}</scfgtu>\n\
             <cfgcpf>{}</cfgcpf><cfgcpt>{}</cfgcpt>\n<cfgmr>{ranges}</cfgmr>\n",
            esc(&self.product),
            esc(&self.calibration_serial),
            esc(&self.force_unit),
            esc(&self.torque_unit),
            self.counts_per_force,
            self.counts_per_torque,
        );
        page.push_str("<comrdte>Enabled</comrdte>");
        if let Some(rate) = self.rdt_rate {
            page.push_str(&format!("<comrdtrate>{rate}</comrdtrate>"));
        }
        if let Some(size) = self.rdt_buffer {
            page.push_str(&format!("<comrdtbsiz>{size}</comrdtbsiz>"));
        }
        page.push_str("\n</netft>\n");
        page
    }

    /// A Gamma SI-130-10 configured in N and N·m, 1 000 000 counts per unit (ATI's catalogue ranges).
    pub fn gamma_si_130_10() -> Self {
        Self {
            product: "Net F/T Gamma SI-130-10".into(),
            calibration_serial: "FT-SIM-130".into(),
            counts_per_force: 1e6,
            counts_per_torque: 1e6,
            force_unit: "N".into(),
            torque_unit: "Nm".into(),
            ranges: [130.0, 130.0, 400.0, 10.0, 10.0, 10.0],
            rdt_rate: Some(1000),
            rdt_buffer: Some(1),
        }
    }

    /// A Nano17 SI-25-0.25 configured in N and N·mm (ranges 25, 25, 35 N and 250 N·mm).
    pub fn nano17_si_25_025() -> Self {
        Self {
            product: "Net F/T Nano17 SI-25-0.25".into(),
            calibration_serial: "FT-SIM-17".into(),
            counts_per_force: 1e6,
            counts_per_torque: 1e3,
            force_unit: "N".into(),
            torque_unit: "Nmm".into(),
            ranges: [25.0, 25.0, 35.0, 250.0, 250.0, 250.0],
            rdt_rate: Some(1000),
            rdt_buffer: Some(1),
        }
    }

    /// A Mini45 US-60-80 configured in lbf and lbf-in (ranges 60, 60, 120 lbf and 80 lbf-in).
    pub fn mini45_us_60_80() -> Self {
        Self {
            product: "Net F/T Mini45 US-60-80".into(),
            calibration_serial: "FT-SIM-45".into(),
            counts_per_force: 1e6,
            counts_per_torque: 1e6,
            force_unit: "lbf".into(),
            torque_unit: "lbf-in".into(),
            ranges: [60.0, 60.0, 120.0, 80.0, 80.0, 80.0],
            rdt_rate: Some(1000),
            rdt_buffer: Some(1),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A page laid out as a box's is (root `netft`, settings the product does not read around the ones
    /// it does, arrays with `;`), written by hand for this test.
    const PAGE: &str = r#"<?xml version="1.0"?><netft>
<runstat>0x00000000</runstat><runrate>7000</runrate>
<runft>12;-3;1000450;0;0;0</runft>
<cfgnam>bench &amp; lab</cfgnam><cfgcalsel>0</cfgcalsel><cfgcalsn>FT12345</cfgcalsn>
<scfgfu>N</scfgfu><scfgtu>Nmm</scfgtu>
<cfgtfx>0;0;10.5;0;0;0</cfgtfx><scfgtdu>mm</scfgtdu><scfgtau>degrees</scfgtau>
<cfgcpf>1000000</cfgcpf><cfgcpt>1000</cfgcpt>
<cfgmr>25;25;35;250;250;250</cfgmr>
<setbias>7;-2;30;1;0;-1</setbias>
<comrdte>Enabled</comrdte><comrdtrate>1000</comrdtrate><comrdtbsiz>4</comrdtbsiz>
<prodname>Net F/T &quot;Nano17&quot;</prodname>
</netft>"#;

    #[test]
    fn a_box_page_gives_its_calibration_in_si() {
        let s = BoxSettings::parse(PAGE).unwrap();
        assert_eq!(s.product, "Net F/T \"Nano17\"");
        assert_eq!(s.calibration_serial, "FT12345");
        assert_eq!((s.counts_per_force, s.counts_per_torque), (1e6, 1e3));
        assert_eq!((s.force_unit.as_str(), s.torque_unit.as_str()), ("N", "Nmm"));
        assert_eq!((s.rdt_rate, s.rdt_buffer), (Some(1000), Some(4)));
        let c = s.calibration().unwrap();
        // 250 N·mm = 0.25 N·m; 1000 counts per N·mm = 10⁶ counts per N·m.
        assert_eq!(c.range, [25.0, 25.0, 35.0, 0.25, 0.25, 0.25]);
        assert_eq!(c.to_si(&[1_000_000, 0, 35_000_000, 250_000, 0, 0]), [1.0, 0.0, 35.0, 0.25, 0.0, 0.0]);
    }

    #[test]
    fn the_simulated_boxes_pages_read_back_as_written() {
        for s in [BoxSettings::gamma_si_130_10(), BoxSettings::nano17_si_25_025(), BoxSettings::mini45_us_60_80()] {
            assert_eq!(BoxSettings::parse(&s.to_xml()).unwrap(), s);
        }
        assert_eq!(BoxSettings::gamma_si_130_10().calibration().unwrap(), Calibration::gamma_si_130_10());
        // 60 lbf = 266.9 N, 80 lbf-in = 9.04 N·m.
        let mini = BoxSettings::mini45_us_60_80().calibration().unwrap();
        assert!((mini.range[0] - 266.893).abs() < 1e-3 && (mini.range[5] - 9.0388).abs() < 1e-4, "{mini:?}");
    }

    #[test]
    fn a_page_without_a_setting_or_with_a_malformed_one_is_refused_with_its_name() {
        let cases = [
            (PAGE.replace("<cfgcpf>1000000</cfgcpf>", ""), "cfgcpf"),
            (PAGE.replace("<cfgcpt>1000</cfgcpt>", "<cfgcpt>NaN</cfgcpt>"), "cfgcpt"),
            (PAGE.replace("<cfgcpt>1000</cfgcpt>", "<cfgcpt>-1</cfgcpt>"), "cfgcpt"),
            (PAGE.replace("<cfgcpf>1000000</cfgcpf>", "<cfgcpf>1e400</cfgcpf>"), "cfgcpf"),
            (PAGE.replace("25;25;35;250;250;250", "25;25;35;250;250"), "cfgmr"),
            (PAGE.replace("25;25;35;250;250;250", "25;25;0;250;250;250"), "cfgmr"),
            (PAGE.replace("<scfgfu>N</scfgfu>", ""), "scfgfu"),
            (PAGE.replace("<comrdtrate>1000</comrdtrate>", "<comrdtrate>fast</comrdtrate>"), "comrdtrate"),
            (PAGE.replace("</netft>", "<cfgcpf>0</cfgcpf></netft>"), "<cfgcpf> appears twice"),
            (PAGE.replace("</netft>", "<scfgfu>k</scfgfu></netft>"), "<scfgfu> appears twice"),
            (format!("{PAGE}<netft><cfgcpf>10</cfgcpf></netft>"), "second root"),
            (PAGE.replace("<cfgcpf>1000000</cfgcpf>", "<cfgcpf>1e300</cfgcpf>"), "cfgcpf"),
            (PAGE.replace("<cfgcpf>1000000</cfgcpf>", "<cfgcpf>0.5</cfgcpf>"), "cfgcpf"),
            (PAGE.replace("25;25;35;250;250;250", "25;25;1e300;250;250;250"), "cfgmr"),
            (PAGE.replace("</netft>", ""), "XML"),
            ("<html><body>404</body></html>".into(), "<html>"),
            ("".into(), "root"),
            ("x".repeat(MAX_PAGE + 1), "bytes"),
        ];
        for (page, named) in cases {
            let e = BoxSettings::parse(&page).map(|_| ()).unwrap_err().to_string();
            assert!(e.contains(named), "{e:?} should name {named}");
        }
        let unit = BoxSettings { torque_unit: "furlong".into(), ..BoxSettings::gamma_si_130_10() };
        assert!(unit.calibration().unwrap_err().to_string().contains("furlong"));
        // 130 N at 10⁸ counts per N is beyond an i32 count: pinned counts could never read as saturated.
        let unreachable = BoxSettings { counts_per_force: 1e8, ..BoxSettings::gamma_si_130_10() };
        assert!(unreachable.calibration().unwrap_err().to_string().contains("Fx's range 130"));
    }

    #[test]
    fn nested_elements_of_the_same_name_are_not_the_setting() {
        let page = PAGE.replace("<runstat>", "<cal><cfgcpf>5</cfgcpf></cal><x:cfgcpf>10</x:cfgcpf><runstat>");
        assert_eq!(BoxSettings::parse(&page).unwrap().counts_per_force, 1e6, "nested or prefixed: another element");
    }
}
