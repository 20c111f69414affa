//! Measurement tables of any instrument, read by `identify` and `discrepancy` besides recordings: CSV or
//! TSV (or `;`-separated), `#` comments, and a header naming each column and its unit:
//!
//! | column | meaning | units |
//! |---|---|---|
//! | `t`, `time` | time | s, ms, µs |
//! | `z`, `indentation`, `deformation`, `depth` | deformation, z > 0 compresses (the surface at z = 0) | m, mm, µm, nm, pm |
//! | `x`, `position`, `displacement`, `extension`, `travel`, `distance` | position along the pressing direction (the surface found from the force onset) | m, mm, µm, nm, pm |
//! | `f`, `force`, `load`, `fz`, `fn` | normal force, f > 0 pushes | kN, N, mN, µN, nN, pN |
//! | `zdot` | deformation rate (optional; else central differences of z or x) | m/s, mm/s, µm/s, nm/s |
//!
//! e.g. `t [s],x [nm],f [nN]` or `Time (s),Load (uN),Indentation (nm)`; names in any case, units as
//! written (`u` for µ too). Other columns are ignored (and said), and so are the lines of an
//! instrument's preamble before the header ([`layout()`]). Columns separated by runs of spaces (an instrument's `.dat` or `.txt` export: `t [s]  x [nm]  f
//! [nN]`) are read too, a unit in brackets belonging to the name before it; in a table separated by tabs,
//! `;` or spaces a decimal comma (`1,5`) reads as a decimal point. Time counts from the first row. Every malformed cell, and every row with more or fewer cells
//! than the header, is an error naming its line (and column); rows of empty cells are skipped. A table of more than [`MAX_ROWS`] rows is read in blocks of rows averaged,
//! so memory stays bounded whatever the file.

use std::path::Path;

use anyhow::{Context, ensure};

mod layout;
use layout::{Separator, layout, reader};

/// The most rows analysed; longer tables are averaged in blocks down to this.
pub const MAX_ROWS: usize = 200_000;

/// How the depth column is meant.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Depth {
    /// `z`: deformation from a known surface.
    Deformation,
    /// `x`: position; the surface is where the force sets on.
    Position,
}

/// A table in SI units (s, m, N, m/s), rows in time order.
#[derive(Debug, Clone)]
pub struct Table {
    pub t: Vec<f64>,
    pub depth: Vec<f64>,
    pub depth_is: Depth,
    pub f: Vec<f64>,
    /// The deformation rate, when the table has it.
    pub rate: Option<Vec<f64>>,
    /// Data rows in the file.
    pub rows: u64,
    /// Rows averaged into each sample (1 unless the table has more than [`MAX_ROWS`]).
    pub block: usize,
    /// Columns the header names that are not read.
    pub ignored: Vec<String>,
    /// Lines of an instrument's preamble before the header, read as comments.
    pub preamble: usize,
}

/// A file is read as a table when its extension says so.
pub fn is_table(path: &Path) -> bool {
    path.is_file()
        && path
            .extension()
            .and_then(|e| e.to_str())
            .is_some_and(|e| ["csv", "tsv", "txt", "dat"].contains(&e.to_ascii_lowercase().as_str()))
}

/// A length as a user writes it, a number in metres or with a unit of [`LENGTH_UNITS`] (`812.5nm`,
/// `0.3 mm`); finite, and at most 1 km either way as a table's depth is.
pub fn parse_length(text: &str) -> Result<f64, String> {
    let text = text.trim();
    // The unit is the longest of LENGTH_UNITS the text ends with; a number's own exponent (`e-7`) is not one.
    let unit = LENGTH_UNITS.iter().filter(|(u, _)| text.ends_with(u)).max_by_key(|(u, _)| u.len());
    let (number, scale) = match unit {
        Some((u, scale)) => (text[..text.len() - u.len()].trim(), *scale),
        None => (text, 1.0),
    };
    let value: f64 = number.parse().map_err(|_| {
        let known: Vec<&str> = LENGTH_UNITS.iter().map(|u| u.0).collect();
        format!("`{text}` is not a length: a number in metres, or with a unit ({})", known.join(", "))
    })?;
    let metres = value * scale;
    // As a table's depth: beyond what an instrument reads is a mistake.
    if metres.is_finite() && metres.abs() <= 1e3 {
        Ok(metres)
    } else {
        Err(format!("`{text}` is not a length an instrument reads (finite, |x| ≤ 1 km)"))
    }
}

const TIME_UNITS: [(&str, f64); 5] = [("s", 1.0), ("sec", 1.0), ("ms", 1e-3), ("µs", 1e-6), ("us", 1e-6)];
const LENGTH_UNITS: [(&str, f64); 7] =
    [("m", 1.0), ("mm", 1e-3), ("µm", 1e-6), ("um", 1e-6), ("nm", 1e-9), ("pm", 1e-12), ("cm", 1e-2)];
const FORCE_UNITS: [(&str, f64); 7] =
    [("kN", 1e3), ("N", 1.0), ("mN", 1e-3), ("µN", 1e-6), ("uN", 1e-6), ("nN", 1e-9), ("pN", 1e-12)];
const SPEED_UNITS: [(&str, f64); 5] = [("m/s", 1.0), ("mm/s", 1e-3), ("µm/s", 1e-6), ("um/s", 1e-6), ("nm/s", 1e-9)];

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Role {
    Time,
    Depth(Depth),
    Force,
    Rate,
}

impl Role {
    /// The role of a column by its name: the short names, and the words instruments export (a
    /// nanoindenter's `Time (s)`, `Load (uN)`, `Indentation (nm)` or `Depth (nm)`; a testing machine's
    /// `Extension (mm)`; a force gauge's `Travel`; a robot's `Fz`).
    fn of(name: &str) -> Option<Self> {
        Some(match name {
            "t" | "time" => Role::Time,
            "z" | "indentation" | "deformation" | "depth" => Role::Depth(Depth::Deformation),
            "x" | "position" | "displacement" | "extension" | "travel" | "distance" => Role::Depth(Depth::Position),
            "f" | "force" | "load" | "fz" | "fn" => Role::Force,
            "zdot" => Role::Rate,
            _ => return None,
        })
    }

    fn units(self) -> &'static [(&'static str, f64)] {
        match self {
            Role::Time => &TIME_UNITS,
            Role::Depth(_) => &LENGTH_UNITS,
            Role::Force => &FORCE_UNITS,
            Role::Rate => &SPEED_UNITS,
        }
    }
}

/// One header cell, `name [unit]` or `name (unit)`, quoted or not: its role, and the unit with the SI
/// value of one unit or why the unit is not read.
fn column(cell: &str, number: usize) -> Option<(Role, anyhow::Result<(String, f64)>)> {
    let cell = cell.trim().trim_matches('"').trim();
    let in_parentheses = || cell.strip_suffix(')').and_then(|c| c.rsplit_once('('));
    let (name, unit) = match (cell.split_once('['), in_parentheses()) {
        (Some((name, rest)), _) => (name.trim(), Some(rest.strip_suffix(']').ok_or(rest))),
        (None, Some((name, unit))) => (name.trim(), Some(Ok(unit))),
        (None, None) => (cell, None),
    };
    let role = Role::of(&name.to_ascii_lowercase())?;
    let units = role.units();
    let names = || units.iter().map(|(u, _)| *u).collect::<Vec<_>>().join(", ");
    let read = match unit {
        None => Err(anyhow::anyhow!(
            "header, column {number} (`{cell}`): `{name}` needs its unit in brackets, one of {}",
            names()
        )),
        Some(Err(_)) => {
            Err(anyhow::anyhow!("header, column {number} (`{cell}`): the unit must close with `]`, e.g. `f [N]`"))
        }
        Some(Ok(unit)) => {
            // The micro sign and the Greek mu are both written for µ.
            let unit = unit.trim().replace('μ', "µ");
            units.iter().find(|(u, _)| *u == unit).map(|&(u, scale)| (u.to_string(), scale)).ok_or_else(|| {
                anyhow::anyhow!("header, column {number} (`{cell}`): unit `{unit}` is not one of {}", names())
            })
        }
    };
    Some((role, read))
}

/// A cell's number; where commas do not separate the columns, a single decimal comma reads as a point.
fn number(cell: &str, sep: Separator) -> Option<f64> {
    cell.parse::<f64>().ok().or_else(|| {
        let decimal_comma = sep != Separator::Byte(b',') && cell.matches(',').count() == 1 && !cell.contains('.');
        decimal_comma.then(|| cell.replace(',', ".").parse().ok()).flatten()
    })
}

/// dx/dt by central differences (one-sided at the ends).
fn central_differences(t: &[f64], x: &[f64]) -> Vec<f64> {
    let n = t.len();
    (0..n)
        .map(|i| {
            let (a, b) = (i.saturating_sub(1), (i + 1).min(n - 1));
            (x[b] - x[a]) / (t[b] - t[a])
        })
        .collect()
}

/// A row the reader cannot split as the header: its line and its cells against the header's.
fn malformed(path: &Path, e: csv::Error) -> anyhow::Error {
    match e.kind() {
        csv::ErrorKind::UnequalLengths { pos, expected_len, len } => anyhow::anyhow!(
            "{}: line {}: {len} cell{} where the header has {expected_len}",
            path.display(),
            pos.as_ref().map_or(0, |p| p.line()),
            if *len == 1 { "" } else { "s" }
        ),
        csv::ErrorKind::Utf8 { pos, .. } => anyhow::anyhow!(
            "{}: line {}: not UTF-8 text (save the table as UTF-8)",
            path.display(),
            pos.as_ref().map_or(0, |p| p.line())
        ),
        _ => anyhow::anyhow!("{}: {e}", path.display()),
    }
}

/// The largest magnitude each column (time, depth, force, rate) may hold, in SI, and how it is said: a
/// thousand times beyond the product's range (10 cm, 10 kN) and a year of recording; a value past it is a
/// corrupted cell or a wrong unit, and would make every fit non-finite.
const READABLE: [(f64, &str); 4] = [
    (3.2e7, "|t| ≤ 1 year"),
    (1e3, "|depth| ≤ 1 km"),
    (softcontact_nodes::contact_estimator::MAX_READABLE_FORCE, "|f| ≤ 10 MN"),
    (1e3, "|ż| ≤ 1 km/s"),
];

/// Reads a table (see the module's doc).
pub fn read(path: &Path) -> anyhow::Result<Table> {
    let layout = layout(path)?;
    let mut rdr = reader(path, layout)?;
    let header = rdr.headers().with_context(|| format!("{}: reading the header", path.display()))?.clone();
    let (at, depth_is, ignored) = header_columns(path, &header).map_err(|e| {
        if layout.found {
            e
        } else {
            e.context(format!(
                "no line among the first {} names a time, a depth and a force column, so the first line that is \
                 not a comment was read as the header",
                layout::MAX_PREAMBLE
            ))
        }
    })?;
    // First pass: the rows, so that a long table is averaged in blocks of equal length.
    let rows = data_rows(path, &mut rdr)?;
    let mut record = csv::StringRecord::new();
    ensure!(rows >= 2, "{}: {rows} data rows; a table needs at least two", path.display());
    let block = usize::try_from(rows.div_ceil(MAX_ROWS as u64)).unwrap_or(usize::MAX);
    let capacity = usize::try_from(rows).unwrap_or(usize::MAX).div_ceil(block);
    let used: Vec<(usize, usize, f64, &str)> = at
        .iter()
        .enumerate()
        .filter_map(|(slot, c)| c.as_ref().map(|(i, _, s)| (slot, *i, *s, header.get(*i).unwrap_or(""))))
        .collect();
    let mut columns: [Vec<f64>; 4] =
        std::array::from_fn(|slot| if at[slot].is_some() { Vec::with_capacity(capacity) } else { Vec::new() });
    let mut sums = [0.0_f64; 4];
    let (mut in_block, mut last_t) = (0_usize, f64::NEG_INFINITY);
    let mut rdr = reader(path, layout)?;
    while rdr.read_record(&mut record).map_err(|e| malformed(path, e))? {
        if record.iter().all(str::is_empty) {
            continue;
        }
        let line = record.position().map_or(0, |p| p.line());
        for &(slot, i, scale, name) in &used {
            let cell = record.get(i).unwrap_or("");
            let value = number(cell, layout.sep).ok_or_else(|| {
                anyhow::anyhow!(
                    "{}: line {line}, column {} (`{name}`): `{cell}` is not a number",
                    path.display(),
                    i + 1
                )
            })?;
            ensure!(
                value.is_finite() && (value * scale).is_finite(),
                "{}: line {line}, column {} (`{name}`): `{cell}` is not a finite number",
                path.display(),
                i + 1
            );
            let (bound, what) = READABLE[slot];
            ensure!(
                (value * scale).abs() <= bound,
                "{}: line {line}, column {} (`{name}`): `{cell}` is beyond what an instrument reads ({what})",
                path.display(),
                i + 1
            );
            if slot == 0 {
                ensure!(
                    value * scale > last_t,
                    "{}: line {line}, column {} (`{name}`): time {cell} is not after the previous row's",
                    path.display(),
                    i + 1
                );
                last_t = value * scale;
            }
            sums[slot] += value * scale;
        }
        in_block += 1;
        if in_block == block {
            for &(slot, ..) in &used {
                columns[slot].push(sums[slot] / block as f64);
                sums[slot] = 0.0;
            }
            in_block = 0;
        }
    }
    let [mut t, depth, f, rate] = columns;
    // Time from the first row: instruments stamp from a trigger (negative before it) or the epoch.
    if let Some(&first) = t.first() {
        t.iter_mut().for_each(|x| *x -= first);
    }
    ensure!(t.len() >= 2, "{}: fewer than two samples after averaging blocks of {block} rows", path.display());
    let preamble = layout.preamble;
    Ok(Table { t, depth, depth_is, f, rate: at[3].as_ref().map(|_| rate), rows, block, ignored, preamble })
}

/// Where the header puts time, depth, force and rate (each: column, unit, scale to SI), whether the depth
/// is a deformation or a position, and the columns not read.
type HeaderColumns = ([Option<(usize, String, f64)>; 4], Depth, Vec<String>);

fn header_columns(path: &Path, header: &csv::StringRecord) -> anyhow::Result<HeaderColumns> {
    let mut at: [Option<(usize, String, f64)>; 4] = Default::default();
    let (mut depth_is, mut ignored, mut unread) = (Depth::Position, Vec::new(), Vec::new());
    for (i, cell) in header.iter().enumerate() {
        let Some((role, read)) = column(cell, i + 1) else {
            // An empty cell (a trailing separator) is no column.
            if !cell.trim().is_empty() {
                ignored.push(cell.trim().to_string());
            }
            continue;
        };
        let slot = match role {
            Role::Time => 0,
            Role::Depth(_) => 1,
            Role::Force => 2,
            Role::Rate => 3,
        };
        let Ok((unit, scale)) = read.map_err(|e| unread.push((slot, cell.trim().to_string(), e))) else { continue };
        if let Role::Depth(d) = role {
            depth_is = d;
        }
        ensure!(
            at[slot].is_none(),
            "{}: header, column {}: `{}` is a second {} column",
            path.display(),
            i + 1,
            cell,
            ["time", "depth (z or x)", "force", "rate"][slot]
        );
        at[slot] = Some((i, unit, scale));
    }
    // A column named for a role in a unit not of that role (a nanoindenter's `Load (V)` beside its
    // `Load (µN)`) is left unread where another column has the role; else it is the error.
    for (slot, cell, e) in unread {
        if at[slot].is_none() {
            return Err(e.context(path.display().to_string()));
        }
        ignored.push(cell);
    }
    for (slot, what) in [(0, "`t [s]`"), (1, "`z [m]` (deformation) or `x [m]` (position)"), (2, "`f [N]`")] {
        ensure!(
            at[slot].is_some(),
            "{}: the header has no {what} column (it has: {}); columns are named t (or time), z (or \
             indentation, deformation, depth), x (or position, displacement, extension, travel, distance), \
             f (or force, load, fz, fn) and zdot, each with its unit in brackets or parentheses, e.g. \
             `t [ms],x [mm],f [N]`, and any other column is left unread",
            path.display(),
            header.iter().collect::<Vec<_>>().join(" | ")
        );
    }
    Ok((at, depth_is, ignored))
}

/// The data rows left in `rdr` (rows of empty cells not counted).
fn data_rows(path: &Path, rdr: &mut csv::Reader<Box<dyn std::io::Read>>) -> anyhow::Result<u64> {
    let mut rows = 0_u64;
    let mut record = csv::StringRecord::new();
    while rdr.read_record(&mut record).map_err(|e| malformed(path, e))? {
        if !record.iter().all(str::is_empty) {
            rows += 1;
        }
    }
    Ok(rows)
}

impl Table {
    /// The median time between samples \[s\].
    pub fn sample_period(&self) -> f64 {
        median(&mut self.t.windows(2).map(|w| w[1] - w[0]).collect::<Vec<f64>>())
    }

    /// The rate of the depth [m/s]: the table's column, else central differences.
    pub fn depth_rate(&self) -> Vec<f64> {
        self.rate.clone().unwrap_or_else(|| central_differences(&self.t, &self.depth))
    }

    /// A length with its SI prefix, for messages.
    pub fn length(&self, metres: f64) -> String {
        si(metres, "m")
    }

    /// A force with its SI prefix, for messages.
    pub fn force(&self, newtons: f64) -> String {
        si(newtons, "N")
    }

    /// A force that goes more than twice as far below its free level as above it, said: f > 0 must push.
    fn pulls(&self, free_level: f64) -> Option<String> {
        let (lo, hi) = extent(&self.f);
        (free_level - lo > 2.0 * (hi - free_level)).then(|| {
            format!(
                "the force goes {} below its free level and only {} above it: f > 0 must push (negate the column if the instrument counts pulling as positive)",
                si(free_level - lo, "N"),
                si(hi - free_level, "N")
            )
        })
    }

    /// The most consecutive samples whose force is more than `threshold` above `free_level`.
    pub fn longest_above(&self, free_level: f64, threshold: f64) -> usize {
        let (mut run, mut most) = (0, 0);
        for &f in &self.f {
            run = if f - free_level > threshold { run + 1 } else { 0 };
            most = most.max(run);
        }
        most
    }

    /// What looks wrong in the table's conventions: a force that mostly pulls (f > 0 must push), a rate
    /// column that disagrees with the depth's own change; and without a rate column, a depth so noisy that
    /// its central differences carry the noise into every rate-dependent term ([`Table::rate_noise`]).
    pub fn doubts(&self, free_level: f64) -> Vec<String> {
        let mut out: Vec<String> = self.pulls(free_level).into_iter().collect();
        // A force that grows as the position falls, where the force itself pushes: the position's sign.
        if out.is_empty() && self.depth_is == Depth::Position && pearson(&self.depth, &self.f) < -0.3 {
            out.push(
                "the force grows as x falls: x must grow as the probe presses in (negate the column if the \
                 instrument counts its position away from the sample)"
                    .to_string(),
            );
        }
        if let Some(rate) = &self.rate {
            let own = central_differences(&self.t, &self.depth);
            let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
            let (rr, oo, ro) = (dot(rate, rate), dot(&own, &own), dot(rate, &own));
            let corr = ro / (rr * oo).sqrt().max(f64::MIN_POSITIVE);
            let ratio = (rr / oo.max(f64::MIN_POSITIVE)).sqrt();
            if !(corr > 0.5 && (0.5..=2.0).contains(&ratio)) {
                out.push(format!(
                    "the zdot column disagrees with the depth's own rate of change (correlation {corr:.2}, size ×{ratio:.3}): check its sign and unit"
                ));
            }
        } else if let Some((depth_noise, rate_noise, speed)) = self.rate_noise(free_level)
            && rate_noise > RATE_NOISE_SHARE * speed
        {
            out.push(format!(
                "the depth's noise (σ {}, from its second differences) makes its rate by central differences noisy \
                 (σ {}, {:.0} % of the speed in contact, whose 95th percentile is {}): the rate-dependent terms (the \
                 law's damping, a drag, a relaxation) read that noise; a zdot column the instrument measured or \
                 smoothed would be better",
                si(depth_noise, "m"),
                si(rate_noise, "m/s"),
                100.0 * rate_noise / speed,
                si(speed, "m/s")
            ));
        }
        out
    }

    /// The depth's white noise σ_x \[m\] (the median absolute second difference, which a smooth motion hardly
    /// moves, over 0.6745·√6), the noise it gives the rate by central differences, σ_x/(√2·dt) [m/s], and
    /// the 95th percentile of the speed where the force is clearly in contact (more than a tenth of its
    /// range above `free_level`). None where there is no such contact or no noise.
    pub fn rate_noise(&self, free_level: f64) -> Option<(f64, f64, f64)> {
        let x = &self.depth;
        if x.len() < 3 {
            return None;
        }
        let mut second: Vec<f64> = x.windows(3).map(|w| (w[2] - 2.0 * w[1] + w[0]).abs()).collect();
        let depth_noise = median(&mut second) / (0.6745 * 6f64.sqrt());
        let dt = self.sample_period();
        let top = self.f.iter().fold(f64::NEG_INFINITY, |a, &b| a.max(b));
        let rate = central_differences(&self.t, x);
        let mut speeds: Vec<f64> = (0..x.len())
            .filter(|&i| self.f[i] - free_level > 0.1 * (top - free_level))
            .map(|i| rate[i].abs())
            .collect();
        if speeds.is_empty() || !(depth_noise > 0.0 && dt > 0.0) {
            return None;
        }
        let k = ((speeds.len() - 1) as f64 * 0.95).round() as usize;
        let speed = *speeds.select_nth_unstable_by(k, f64::total_cmp).1;
        (speed > 0.0).then_some((depth_noise, depth_noise / (2f64.sqrt() * dt), speed))
    }
}

/// A rate by central differences whose noise exceeds this share of the speed in contact is doubted
/// ([`Table::doubts`]): on the AFM curves read at the instrument's own rate it is 13–34 %, on those
/// averaged in blocks at most 6 %.
pub const RATE_NOISE_SHARE: f64 = 0.1;

/// `value` with the SI prefix that puts it between 1 and 1000 (k down to p), e.g. `4.640 nN`.
pub fn si(value: f64, unit: &str) -> String {
    if !value.is_finite() {
        return format!("{value} {unit}");
    }
    // Rounded to three decimals, a magnitude under 0.0005 pN is zero, with no sign.
    if value.abs() < 5e-16 {
        return format!("0 {unit}");
    }
    // Past the largest prefix by a thousand: in powers of ten, not in hundreds of digits.
    if value.abs() >= 1e6 {
        return format!("{value:.3e} {unit}");
    }
    // Rounded to three decimals, 999.9996 reads as 1.000 of the next prefix.
    let (prefix, scale) = prefix(value.abs() / (1.0 - 5e-4));
    format!("{:.3} {prefix}{unit}", value / scale)
}

/// The SI prefix (k down to p) and its scale that put `magnitude` between 1 and 1000.
pub fn prefix(magnitude: f64) -> (&'static str, f64) {
    const PREFIXES: [(&str, f64); 6] = [("k", 1e3), ("", 1.0), ("m", 1e-3), ("µ", 1e-6), ("n", 1e-9), ("p", 1e-12)];
    PREFIXES.iter().copied().find(|(_, s)| magnitude >= *s).unwrap_or(PREFIXES[5])
}

/// Where the contact begins: what the table's own free part says.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Onset {
    /// The force read with nothing touching \[N\]; where the table starts in contact, see [`Start`].
    pub free_level: f64,
    /// The free part's noise \[N\], from its first differences (a slow trend does not inflate it).
    pub noise: f64,
    /// The force above the free level that counts as contact \[N\].
    pub threshold: f64,
    /// Samples before the contact (the free part), 0 when the table starts in contact.
    pub free_samples: usize,
    /// Samples at the start passed over as free space although the force rose beyond the threshold there
    /// (a wave felt in free space, see [`first_contact`]): where the contact detector starts to look.
    pub passed_over: usize,
    pub start: Start,
}

/// How the table begins, and so where its force's zero comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Start {
    /// A free part before the contact: the force is zeroed at its mean.
    Free,
    /// The head's force moves by more than the onset threshold: the table starts in contact.
    InContact,
    /// The force is flat before its onset, but the depth hardly moves there: a pause held at one depth,
    /// which says nothing of whether anything touches (the force rises as soon as the depth moves).
    Paused,
}

/// The share of the table read as its free start before the onset is known...
const HEAD_SHARE: f64 = 0.02;
/// ...at most this many samples (a long record of many pushes may touch within its first 2 %)...
const HEAD_MAX: usize = 500;
/// ...and at least this many, or the flat start before the force first moves by the threshold where that
/// is shorter than the head and longer than this.
const HEAD_MIN: usize = 20;
/// The onset threshold: this many noise σ above the free level...
const ONSET_SIGMAS: f64 = 10.0;
/// ...and at least this share of the table's force range.
const ONSET_SHARE: f64 = 0.02;
/// A flat force before the onset is free space only where the depth travels there by at least this
/// share of its range in the table: an approach moves the probe toward the surface with nothing felt.
const FREE_TRAVEL_SHARE: f64 = 0.1;

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// The least and the largest value of a column.
pub fn extent(v: &[f64]) -> (f64, f64) {
    v.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| (a.min(v), b.max(v)))
}

fn range(v: &[f64]) -> f64 {
    let (lo, hi) = extent(v);
    hi - lo
}

/// The correlation coefficient of two columns (0 where either is constant).
fn pearson(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len().min(b.len()) as f64;
    let (ma, mb) = (a.iter().sum::<f64>() / n, b.iter().sum::<f64>() / n);
    let (mut ab, mut aa, mut bb) = (0.0, 0.0, 0.0);
    for (x, y) in a.iter().zip(b) {
        ab += (x - ma) * (y - mb);
        aa += (x - ma) * (x - ma);
        bb += (y - mb) * (y - mb);
    }
    if aa > 0.0 && bb > 0.0 { ab / (aa * bb).sqrt() } else { 0.0 }
}

/// The noise σ of a force stretch from its first differences (robust, and at least a quantised
/// reading's rounding: [`softcontact_discrepancy::robust_noise_of_differences`]).
fn noise_of(s: &[f64]) -> f64 {
    let mut d: Vec<f64> = s.windows(2).map(|w| w[1] - w[0]).collect();
    softcontact_discrepancy::robust_noise_of_differences(&mut d)
}

/// The least samples with z ≤ 0 before a deformation table's contact that give its free level.
const MIN_FREE_DEFORMATION: usize = 5;

impl Table {
    /// Where the contact begins ([`Onset`]). A table of deformations says itself where nothing touches
    /// (z ≤ 0): its samples before the first z > 0, where there are at least [`MIN_FREE_DEFORMATION`], are
    /// its free part (a viscoelastic sample unloaded fast reads a force below that level later, which is
    /// no reason to move its zero). A table of positions, or of deformations starting in contact: [`onset`].
    pub fn onset(&self) -> Onset {
        let first = self.depth.iter().position(|&z| z > 0.0).unwrap_or(self.depth.len());
        if self.depth_is != Depth::Deformation || first < MIN_FREE_DEFORMATION {
            return onset(&self.f, &self.depth);
        }
        let free = &self.f[..first];
        let noise = noise_of(free);
        Onset {
            free_level: free.iter().sum::<f64>() / free.len() as f64,
            noise: noise.max(f64::MIN_POSITIVE),
            threshold: (ONSET_SIGMAS * noise).max(ONSET_SHARE * range(&self.f)),
            free_samples: free.len(),
            passed_over: 0,
            start: Start::Free,
        }
    }
}

/// The free level, the noise and the onset threshold of a force column and its depth (see [`Onset`]).
/// The head of the table (its first 2 %, at least 20 samples and at most 500, cut to its flat start where
/// the force moves within it) gives a first level and noise. The table starts in contact where the head's force moves by more than the threshold, or where
/// the depth travels less than [`FREE_TRAVEL_SHARE`] of its range before the onset. Starting in contact,
/// the force keeps the instrument's zero, unless the table goes below it by more than the threshold: a
/// contact only pushes, so the least force of the table is then its zero (the highest free level consistent with a record that never
/// pulls), where the table is not mostly below the zero (a force counted positive when pulling).
pub fn onset(f: &[f64], depth: &[f64]) -> Onset {
    let n = f.len();
    let mut head = ((n as f64 * HEAD_SHARE) as usize).clamp(HEAD_MIN, HEAD_MAX).min(n);
    let mut level0 = median(&mut f[..head].to_vec());
    let noise0 = noise_of(&f[..head]);
    let threshold = (ONSET_SIGMAS * noise0).max(ONSET_SHARE * range(f));
    let in_contact = |start: Start| {
        let (least, most) = extent(f);
        // Below the zero by more than the noise reaches (the onset threshold), and not mostly below it:
        // mostly is a force counted positive when pulling ([`Table::doubts`] says so).
        let free_level = if least < -threshold && -least <= 2.0 * most { least } else { 0.0 };
        Onset { free_level, noise: noise0, threshold, free_samples: 0, passed_over: 0, start }
    };
    if f[..head].iter().any(|v| (v - level0).abs() > threshold) {
        // A head longer than a short flat start (a long record whose ramp begins within its first 2 %):
        // the flat start alone is the head.
        let short = HEAD_MIN.min(n);
        let level = median(&mut f[..short].to_vec());
        let flat = f.iter().position(|v| (v - level).abs() > threshold).unwrap_or(n);
        if flat < short {
            return in_contact(Start::InContact);
        }
        (head, level0) = (flat, median(&mut f[..flat].to_vec()));
    }
    let (first, passed_over) = first_contact(f, depth, level0, threshold);
    if range(&depth[..first.max(1).min(depth.len())]) < FREE_TRAVEL_SHARE * range(depth) {
        return in_contact(Start::Paused);
    }
    // The last tenth before the onset may already feel the surface (long-range forces). A wave the free
    // part carries beyond the threshold (before the contact, see [`first_contact`]) is no part of its level.
    let free = &f[..(first - first / 10).max(head.min(first))];
    let flat = || free.iter().filter(|v| (*v - level0).abs() <= threshold);
    let free_level = flat().sum::<f64>() / flat().count().max(1) as f64;
    Onset {
        free_level,
        noise: noise_of(free).max(f64::MIN_POSITIVE),
        threshold,
        free_samples: free.len(),
        passed_over,
        start: Start::Free,
    }
}

/// The first sample of the first excursion of the force beyond `threshold` above `level` that is a
/// contact. An excursion lasts until the force is back within half the threshold of the level for as
/// many samples as the contact detector's confirmation asks (noise about the threshold does not cut it),
/// and is a contact only where it lasts that many samples. A force that falls back to the level while the depth presses on, after its
/// peak, by more than a quarter of its travel to that peak was not pushed by a surface: such an excursion
/// is felt in free space (an optical interference wave in an AFM's deflection, an arm's inertial
/// transient), and the search goes on after it. A contact ends as the depth comes back, or relaxes where
/// it is held. Where no excursion is a contact, the first sample above the threshold. Also returns where
/// the last excursion passed over ends (0 where none was).
fn first_contact(f: &[f64], depth: &[f64], level: f64, threshold: f64) -> (usize, usize) {
    let n = f.len().min(depth.len());
    let confirm = softcontact_contact::OnsetConfig::default().confirm;
    let above = |from: usize| (from..n).find(|&i| f[i] - level > threshold).unwrap_or(n);
    let (mut start, mut passed_over) = (above(0), 0);
    while start < n {
        let back = |i: usize| f[i] - level <= 0.5 * threshold;
        let end = (start..n).find(|&i| (i..(i + confirm).min(n)).all(back)).unwrap_or(n);
        let peak = (start..end).max_by(|&a, &b| f[a].total_cmp(&f[b])).unwrap_or(start);
        let pressed_on = depth[end - 1] - depth[peak] > 0.25 * (depth[peak] - depth[start]);
        if end == n || (end - start >= confirm && !pressed_on) {
            return (start, passed_over);
        }
        passed_over = end;
        start = above(end);
    }
    (above(0).min(f.len()), 0)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn table(text: &str) -> (tempfile::TempDir, std::path::PathBuf) {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("t.csv");
        std::fs::write(&path, text).unwrap();
        (dir, path)
    }

    #[test]
    fn a_length_is_read_in_metres_or_with_its_unit_and_anything_else_is_refused() {
        assert_eq!(parse_length("1.5e-7"), Ok(1.5e-7));
        assert_eq!(parse_length("-4.1e-5"), Ok(-4.1e-5));
        assert!((parse_length("2e2 nm").unwrap() - 2e-7).abs() < 1e-20);
        assert!((parse_length("812.5nm").unwrap() - 812.5e-9).abs() < 1e-20);
        assert!((parse_length(" 0.3 mm").unwrap() - 3e-4).abs() < 1e-18);
        assert!((parse_length("79.4pm").unwrap() - 79.4e-12).abs() < 1e-24);
        assert!((parse_length("-2µm").unwrap() + 2e-6).abs() < 1e-18);
        for bad in ["", "nm", "1 furlong", "NaN", "inf", "1e400", "1e300", "-1e300", "1e300 cm", "1001", "1..2nm"] {
            assert!(parse_length(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn units_are_converted_to_si_and_comments_skipped() {
        let (_d, p) = table("# an instrument's export\nt [ms],x [µm],f [mN],extra\n0,1,2,a\n# mid\n10,3,4,b\n");
        let t = read(&p).unwrap();
        assert_eq!(t.t, vec![0.0, 0.01]);
        assert!((t.depth[1] - 3e-6).abs() < 1e-18);
        assert!((t.f[1] - 4e-3).abs() < 1e-15);
        assert_eq!(t.depth_is, Depth::Position);
        assert_eq!(t.ignored, vec!["extra".to_string()]);
        // A trailing separator is no column to list.
        let (_d, p) = table("t [s],x [mm],f [N],\n0,1,2,\n1,3,4,\n");
        assert!(read(&p).unwrap().ignored.is_empty());
    }

    #[test]
    fn tabs_and_greek_mu_and_a_deformation_column() {
        let (_d, p) = table("z [μm]\tT [s]\tF[nN]\tzdot [nm/s]\n1\t0\t5\t2\n2\t1\t6\t3\n");
        let t = read(&p).unwrap();
        assert_eq!(t.depth_is, Depth::Deformation);
        assert!((t.f[0] - 5e-9).abs() < 1e-20);
        assert!((t.rate.unwrap()[1] - 3e-9).abs() < 1e-20);
    }

    #[test]
    fn columns_separated_by_runs_of_spaces_and_decimal_commas() {
        let text = "# a .dat export\n  t [s]    x   [nm]   f [nN]  \n\n  0.0   1,5   2\n 0.5\t\t2.5  -3  \n";
        let (_d, p) = table(text);
        let t = read(&p).unwrap();
        assert_eq!(t.t, vec![0.0, 0.5]);
        assert!((t.depth[0] - 1.5e-9).abs() < 1e-20 && (t.depth[1] - 2.5e-9).abs() < 1e-20, "{:?}", t.depth);
        assert!((t.f[1] + 3e-9).abs() < 1e-20);
        // A row with a cell too few is still named by its line.
        let (_d, p) = table("t [s]  x [m]  f [N]\n0 0 0\n1 0\n");
        let e = format!("{:#}", read(&p).unwrap_err());
        assert!(e.contains("line 3: 2 cells where the header has 3"), "{e}");
        // `;` tables take decimal commas; comma-separated ones cannot have them.
        let (_d, p) = table("t [s];x [mm];f [N]\n0;0,25;1,5\n1;0,5;2\n");
        let t = read(&p).unwrap();
        assert!((t.depth[0] - 0.25e-3).abs() < 1e-15 && (t.f[0] - 1.5).abs() < 1e-12);
        let (_d, p) = table("t [s];x [mm];f [N]\n0;0,2,5;1\n1;0;2\n");
        assert!(format!("{:#}", read(&p).unwrap_err()).contains("`0,2,5` is not a number"));
    }

    #[test]
    fn an_instruments_export_with_a_preamble_and_units_in_parentheses_is_read_as_saved() {
        // A nanoindenter's text export as saved: settings one per line (a Latin-1 µ among them, a `Time`
        // that is a clock, a blank line), then the header in words with units in parentheses.
        let mut bytes = b"Date\t12/05/2025\tTime\t11:20:38\tStatus\tOK\nk (N/m)\t0.019\n\nMax load (".to_vec();
        bytes.push(0xB5);
        bytes.extend(b"N)\t0.050\nComment: \n\nTime (s)\tLoad (uN)\tIndentation (nm)\tPiezo (nm)\n");
        bytes.extend(b"0.000\t-0.0003\t0.0\t64.9\n0.001\t0.0021\t1.5\t66.0\n0.002\tx\t2.5\t67.1\n");
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("Indentation_002.txt");
        std::fs::write(&path, &bytes).unwrap();
        let e = format!("{:#}", read(&path).unwrap_err());
        assert!(e.contains("line 10, column 2 (`Load (uN)`): `x` is not a number"), "{e}");
        bytes.truncate(bytes.len() - b"0.002\tx\t2.5\t67.1\n".len());
        std::fs::write(&path, &bytes).unwrap();
        let t = read(&path).unwrap();
        assert_eq!(t.preamble, 6);
        assert_eq!(t.depth_is, Depth::Deformation);
        assert_eq!(t.ignored, vec!["Piezo (nm)".to_string()]);
        assert_eq!(t.t, vec![0.0, 0.001]);
        assert!((t.f[1] - 0.0021e-6).abs() < 1e-18 && (t.depth[1] - 1.5e-9).abs() < 1e-20, "{t:?}");
        // The same with its columns separated by runs of spaces.
        let spaced = String::from_utf8_lossy(&bytes).replace('\t', "   ");
        std::fs::write(&path, spaced).unwrap();
        let t = read(&path).unwrap();
        assert_eq!((t.preamble, t.t.len()), (6, 2));
    }

    #[test]
    fn a_testing_machines_quoted_export_and_an_extra_column_in_another_unit_are_read() {
        // Quoted cells, a quoted preamble, a testing machine's names; `Load (V)` (a raw channel) is left
        // unread beside `Load (µN)`, and a role's unit it does not read is the error only where no other
        // column has the role.
        let (_d, p) = table(
            "\"Specimen\",\"1\"\n\"\"\n\"Time (sec)\",\"Extension (mm)\",\"Load (N)\"\n\"0\",\"0\",\"0\"\n\"1\",\"1\",\"2\"\n",
        );
        let t = read(&p).unwrap();
        assert_eq!((t.preamble, t.depth_is, t.t.clone()), (2, Depth::Position, vec![0.0, 1.0]));
        assert!((t.depth[1] - 1e-3).abs() < 1e-15 && (t.f[1] - 2.0).abs() < 1e-12, "{t:?}");
        let (_d, p) = table("Depth (nm)\tLoad (µN)\tTime (s)\tDepth (V)\tLoad (V)\n0\t0\t0\t0\t0\n1\t2\t1\t0.1\t0.2\n");
        let t = read(&p).unwrap();
        assert_eq!(t.depth_is, Depth::Deformation);
        assert_eq!(t.ignored, vec!["Depth (V)".to_string(), "Load (V)".to_string()]);
        assert!((t.f[1] - 2e-6).abs() < 1e-18, "{t:?}");
        let (_d, p) = table("t [s],x [m],Fz [V]\n0,0,0\n1,1,1\n");
        let e = format!("{:#}", read(&p).unwrap_err());
        assert!(e.contains("column 3 (`Fz [V]`): unit `V` is not one of kN, N"), "{e}");
    }

    #[test]
    fn malformed_cells_are_named_by_line_and_column() {
        for (text, says) in [
            ("t [s],x [m],f [N]\n0,0,0\n1,0,abc\n", "line 3, column 3 (`f [N]`): `abc` is not a number"),
            ("t [s],x [m],f [N]\n0,0,0\n1,NaN,0\n", "line 3, column 2 (`x [m]`): `NaN` is not a finite number"),
            ("t [s],x [m],f [N]\n0,0,0\n0,1,inf\n", "line 3, column 1 (`t [s]`): time 0 is not after"),
            ("t [s],x [m],f [kN]\n0,0,1e306\n1,0,0\n", "line 2, column 3 (`f [kN]`): `1e306` is not a finite"),
            ("t [s],x [m],f [N]\n0,0,0\n1,1e300,0\n", "line 3, column 2 (`x [m]`): `1e300` is beyond what an"),
            ("t [s],z [nm],f [mN]\n0,0,2e13\n1,0,0\n", "line 2, column 3 (`f [mN]`): `2e13` is beyond"),
            ("t [s],x [furlong],f [N]\n0,0,0\n", "unit `furlong` is not one of m, mm"),
            ("t,x [m],f [N]\n0,0,0\n", "`t` needs its unit in brackets"),
            ("t [s],f [N]\n0,0\n1,1\n", "no `z [m]` (deformation) or `x [m]` (position) column"),
            ("t [s],x [m],f [N]\n0,0,0\n", "1 data rows"),
            ("# only comments\n", "no header line"),
            ("t [s],x [m],f [N]\n0,0,0\n1,0\n", "line 3: 2 cells where the header has 3"),
            ("t [s],x [m],x [m],f [N]\n0,0,0,0\n", "second depth"),
        ] {
            let (_d, p) = table(text);
            let e = format!("{:#}", read(&p).expect_err(text));
            assert!(e.contains(says), "{text:?}: {e}");
        }
    }

    #[test]
    fn a_long_table_is_averaged_in_blocks_of_equal_length() {
        let n = MAX_ROWS * 2 + 1;
        let mut text = String::from("t [s],x [µm],f [N]\n");
        for i in 0..n {
            text.push_str(&format!("{i},{i},1\n"));
        }
        let (_d, p) = table(&text);
        let t = read(&p).unwrap();
        assert_eq!(t.block, 3);
        assert_eq!(t.rows, n as u64);
        assert_eq!(t.t.len(), n / 3);
        assert_eq!(t.t[1], 3.0, "blocks' mean times, from the first block's");
    }

    #[test]
    fn si_prefixes() {
        assert_eq!(si(4.64e-9, "N"), "4.640 nN");
        assert_eq!(si(-0.0123, "m"), "-12.300 mm");
        assert_eq!(si(2500.0, "N"), "2.500 kN");
        assert_eq!(si(0.0, "N"), "0 N");
        assert_eq!(si(-0.0, "N"), "0 N");
        assert_eq!(si(-1e-17, "N"), "0 N");
        assert_eq!(si(3e-15, "N"), "0.003 pN");
        assert_eq!(si(2e13, "N"), "2.000e13 N");
        assert_eq!(si(-1e300, "m"), "-1.000e300 m");
        assert_eq!(si(999_999.0, "N"), "999.999 kN");
    }

    #[test]
    fn the_onset_is_scale_free() {
        // The same shape at 1 nN and at 10 kN: the same onset sample, thresholds in proportion.
        let shape: Vec<f64> = (0..1000)
            .map(|i| {
                let noise = ((i * 7919) % 101) as f64 / 100.0 - 0.5;
                let push = if i > 600 { ((i - 600) as f64 / 400.0).powf(1.5) } else { 0.0 };
                0.3 + push + 0.002 * noise
            })
            .collect();
        let at = |scale: f64| {
            let f: Vec<f64> = shape.iter().map(|v| v * scale).collect();
            let depth: Vec<f64> = (0..f.len()).map(|i| i as f64 * 1e-6).collect();
            let o = onset(&f, &depth);
            (o, f.iter().position(|v| v - o.free_level > o.threshold))
        };
        let (small, i_small) = at(1e-9);
        let (large, i_large) = at(1e4);
        assert_eq!(i_small, i_large);
        assert!(i_small.unwrap() > 600 && i_small.unwrap() < 650, "{i_small:?}");
        assert!((small.threshold / 1e-9 - large.threshold / 1e4).abs() < 1e-9 * large.threshold / 1e4);
        assert!((small.free_level / 1e-9 - 0.3).abs() < 1e-3);
        assert!(small.free_samples > 500);
    }

    #[test]
    fn time_counts_from_the_first_row_and_doubtful_conventions_are_said() {
        // Stamped from a trigger (negative before it), the force counted positive when pulling, and a
        // rate column in the wrong unit.
        let mut text = String::from("t [s],x [mm],f [N],zdot [mm/s]\n");
        for i in 0..200 {
            let x = -1.0 + i as f64 * 0.01;
            let f = if x > 0.0 { -50.0 * x } else { 0.0 };
            text.push_str(&format!("{},{x},{f},{}\n", -2.6 + i as f64 * 0.01, 1000.0));
        }
        let (_d, p) = table(&text);
        let t = read(&p).unwrap();
        assert_eq!(t.t[0], 0.0);
        assert!((t.t[199] - 1.99).abs() < 1e-9);
        let doubts = t.doubts(onset(&t.f, &t.depth).free_level);
        assert!(doubts.iter().any(|d| d.contains("f > 0 must push")), "{doubts:?}");
        assert!(!doubts.iter().any(|d| d.contains("x must grow")), "{doubts:?}");
        assert!(doubts.iter().any(|d| d.contains("zdot column disagrees")), "{doubts:?}");
        // As it should be: no doubt.
        let good = Table { f: t.f.iter().map(|f| -f).collect(), rate: None, ..t };
        assert!(good.doubts(0.0).is_empty(), "{:?}", good.doubts(0.0));
        // The position counted away from the sample: the force grows as x falls.
        let away = Table { depth: good.depth.iter().map(|x| -x).collect(), ..good };
        assert!(away.doubts(0.0).iter().any(|d| d.contains("x must grow")), "{:?}", away.doubts(0.0));
    }

    /// A push in and out at 5 µm/s sampled every 0.5 ms (an AFM curve at the instrument's rate): with the
    /// depth's noise at 2 nm its central differences carry σ 2.8 µm/s, which the doubt names; at 0.05 nm
    /// (71 nm/s) and with a rate column there is none.
    #[test]
    fn a_depth_too_noisy_for_its_central_differences_is_doubted() {
        let (dt, speed, n) = (5e-4, 5e-6, 2000);
        // A uniform noise of σ `sigma` from a fixed linear congruential sequence, not the library's.
        let noisy = |sigma: f64| -> Table {
            let mut state = 12345u64;
            let mut noise = || {
                state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                ((state >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * sigma * 12f64.sqrt()
            };
            let t: Vec<f64> = (0..n).map(|i| i as f64 * dt).collect();
            // Free for the first half, then in 0.25 s and out in 0.25 s.
            let true_depth =
                |t: f64| -> f64 { if t < 0.5 { speed * (t - 0.5) } else { speed * (0.25 - (t - 0.75).abs()) } };
            let depth: Vec<f64> = t.iter().map(|&t| true_depth(t) + noise()).collect();
            let f = t.iter().map(|&t| 1e3 * true_depth(t).max(0.0)).collect();
            Table {
                t,
                depth,
                depth_is: Depth::Deformation,
                f,
                rate: None,
                rows: n as u64,
                block: 1,
                ignored: vec![],
                preamble: 0,
            }
        };
        let loud = noisy(2e-9);
        let (depth_noise, rate_noise, fastest) = loud.rate_noise(0.0).unwrap();
        assert!((depth_noise / 2e-9 - 1.0).abs() < 0.15, "σ_x {depth_noise}");
        assert!((rate_noise / (2e-9 / (2f64.sqrt() * dt)) - 1.0).abs() < 0.15, "σ_v {rate_noise}");
        assert!(fastest > speed, "{fastest}");
        let doubts = loud.doubts(0.0);
        assert!(doubts.iter().any(|d| d.contains("central differences noisy")), "{doubts:?}");
        let quiet = noisy(5e-11);
        assert!(quiet.doubts(0.0).is_empty(), "{:?}", quiet.doubts(0.0));
        let measured = Table { rate: Some(vec![0.0; n]), ..loud };
        assert!(!measured.doubts(0.0).iter().any(|d| d.contains("central differences noisy")));
    }

    #[test]
    fn a_long_record_of_many_pushes_has_its_free_start_found() {
        // 100,000 samples, the first push at 1.5 %: within 2 % of the record, not within 500 samples.
        let f: Vec<f64> = (0..100_000)
            .map(|i| {
                let noise = ((i * 7919) % 101) as f64 / 100.0 - 0.5;
                let phase = ((i + 1000) % 10_000) as f64 / 10_000.0;
                let z = (1.0 - (2.0 * phase - 1.0).abs()) * 2.0 - 1.0;
                2.0 + 10.0 * z.max(0.0).powf(1.5) + 0.01 * noise
            })
            .collect();
        let depth: Vec<f64> = (0..100_000).map(|i| (((i + 1000) % 10_000) as f64 / 5_000.0 - 1.0).abs()).collect();
        let o = onset(&f, &depth);
        assert!(o.free_samples > 100, "{o:?}");
        assert!((o.free_level - 2.0).abs() < 0.01, "{o:?}");
        assert_eq!(o.start, Start::Free);
    }

    #[test]
    fn a_wave_in_free_space_beyond_the_threshold_is_no_contact_and_no_part_of_the_free_level() {
        // An approach at constant speed whose deflection carries an interference wave of 4 % of the peak
        // (beyond the 2 % threshold) before a linear contact at x = 0.8 µm, pressed to 1 µm and withdrawn.
        let n = 1200;
        let depth: Vec<f64> = (0..n).map(|i| 1e-6 * (1.0 - ((i as f64 - 600.0) / 600.0).abs())).collect();
        let f: Vec<f64> = depth
            .iter()
            .enumerate()
            .map(|(i, &x)| {
                let wave = if (60..310).contains(&i) {
                    4.0 * (std::f64::consts::TAU * (i - 60) as f64 / 250.0).sin()
                } else {
                    0.0
                };
                137.0 + wave + 5e8 * (x - 0.8e-6).max(0.0) + 0.02 * (((i * 7919) % 101) as f64 / 100.0 - 0.5)
            })
            .collect();
        let o = onset(&f, &depth);
        assert_eq!(o.start, Start::Free, "{o:?}");
        let (first, passed_over) = first_contact(&f, &depth, o.free_level, o.threshold);
        assert!((depth[first] - 0.8e-6 - o.threshold / 5e8).abs() < 2e-9, "onset at {} m", depth[first]);
        assert!(passed_over > 160 && passed_over < 310 && o.passed_over == passed_over, "{passed_over}: {o:?}");
        assert!((o.free_level - 137.0).abs() < 0.1, "{o:?}");
        // The same wave with the depth held within it: a contact that relaxed, the first.
        let held: Vec<f64> = (0..n).map(|i| if (60..310).contains(&i) { depth[60] } else { depth[i] }).collect();
        assert_eq!(first_contact(&f, &held, 137.0, o.threshold).1, 0);
        assert!(first_contact(&f, &held, 137.0, o.threshold).0 < 310);
    }

    #[test]
    fn a_table_that_starts_in_contact_has_no_free_level() {
        let f: Vec<f64> = (0..500).map(|i| 5.0 * (-(i as f64) / 100.0).exp() + 1.0).collect();
        let o = onset(&f, &vec![1e-3; 500]);
        assert_eq!(o.free_level, 0.0);
        assert_eq!(o.free_samples, 0);
        assert_eq!(o.start, Start::InContact);
        // Counted positive when pulling: the zero stays the instrument's, for the doubt to see.
        let pulling: Vec<f64> = f.iter().map(|v| -v).collect();
        assert_eq!(onset(&pulling, &vec![1e-3; 500]).free_level, 0.0);
    }

    #[test]
    fn a_pause_held_in_contact_is_not_free_space_and_the_least_force_is_the_zero() {
        // Held still for 100 samples at an unknown preload read as -100 (the instrument's zero is not the
        // free level), then pushed further, held, and withdrawn past where it started: the force falls to
        // -235, below where the pause read it, and the record ends in contact.
        let mut depth = vec![0.0; 100];
        depth.extend((0..200).map(|i| i as f64 * 1e-8));
        depth.extend(vec![2e-6; 500]);
        depth.extend((0..250).map(|i| 2e-6 - i as f64 * 1e-8));
        let f: Vec<f64> = (0..depth.len())
            .map(|i| {
                let relaxed = if i >= 300 { 60.0 * (1.0 - (-((i - 300) as f64) / 100.0).exp()) } else { 0.0 };
                -100.0 + 1.5e8 * depth[i] - relaxed + 0.01 * (((i * 7919) % 101) as f64 / 100.0 - 0.5)
            })
            .collect();
        let o = onset(&f, &depth);
        assert_eq!(o.start, Start::Paused, "{o:?}");
        assert_eq!(o.free_samples, 0);
        let least = f.iter().fold(f64::INFINITY, |a, &b| a.min(b));
        assert!(least < -200.0 && o.free_level == least, "{o:?}");
        // The same force with the depth moving before the onset: an approach, zeroed at its mean.
        let moving: Vec<f64> =
            depth.iter().enumerate().map(|(i, d)| d - 2e-6 * (1.0 - i.min(100) as f64 / 100.0)).collect();
        let free = onset(&f, &moving);
        assert_eq!(free.start, Start::Free, "{free:?}");
        assert!((free.free_level + 100.0).abs() < 0.01, "{free:?}");
    }

    /// A deformation table says itself where nothing touches: its samples at z ≤ 0 before the contact are
    /// its free part, although the depth does not travel there and a fast unloading of a viscoelastic
    /// sample later reads 0.3 N below that level (which moved the zero by 0.3 N when the table was read as
    /// starting in contact). Without such a start, the force's own onset as before.
    #[test]
    fn a_deformation_table_is_zeroed_where_its_depth_says_nothing_touches() {
        let (_d, p) = table(
            &std::iter::once("t [s],z [mm],f [N]".to_string())
                .chain((0..400).map(|i| {
                    let z = if i < 50 {
                        0.0
                    } else if i < 150 {
                        (i - 50) as f64 * 0.05
                    } else {
                        0.0
                    };
                    let f = if (50..150).contains(&i) {
                        0.3 * z
                    } else if i >= 150 {
                        -0.3
                    } else {
                        0.02
                    };
                    format!("{},{z},{}", i as f64 * 0.02, f + 0.001 * ((i * 7919) % 7) as f64)
                }))
                .collect::<Vec<_>>()
                .join("\n"),
        );
        let t = read(&p).unwrap();
        let o = t.onset();
        assert_eq!((o.start, o.free_samples), (Start::Free, 51), "{o:?}");
        assert!((o.free_level - 0.023).abs() < 0.002, "{o:?}");
        let in_contact = Table { depth: t.depth.iter().map(|z| z + 1e-4).collect(), ..t.clone() };
        assert_eq!(in_contact.onset(), onset(&in_contact.f, &in_contact.depth));
    }

    /// A long record whose ramp begins within its first 2 % (a second at rest, then a ramp and a hold of
    /// many minutes): the head is cut to the flat start, which is not taken for a contact; and a force
    /// that goes below the instrument's zero by less than the threshold (the noise's extreme) keeps it.
    #[test]
    fn a_ramp_within_the_head_leaves_the_flat_start_as_the_head_and_a_noise_dip_keeps_the_zero() {
        let n = 20_000;
        let depth: Vec<f64> =
            (0..n).map(|i| if i < 50 { 0.0 } else { 1e-3 * ((i - 50) as f64 / 100.0).min(1.0) }).collect();
        let f: Vec<f64> = (0..n)
            .map(|i| {
                let pressed = 100.0 * depth[i] * (1.0 + (-(i as f64) / 5000.0).exp());
                if i == n - 10 { -0.003 } else { pressed + 1e-4 * ((i * 7919) % 11) as f64 }
            })
            .collect();
        let o = onset(&f, &depth);
        assert_eq!(o.start, Start::Paused, "{o:?}");
        assert_eq!(o.free_level, 0.0, "{o:?}");
        let moving: Vec<f64> =
            depth.iter().enumerate().map(|(i, d)| d - 1e-4 * (50usize.saturating_sub(i)) as f64).collect();
        let free = onset(&f, &moving);
        assert_eq!(free.start, Start::Free, "{free:?}");
        assert!(free.free_samples >= 20 && free.free_samples <= 60, "{free:?}");
    }

    /// A byte-order mark before a comment line: the separator is read from the header after it (it was
    /// read from the marked comment, and the header's commas were taken for part of a unit).
    #[test]
    fn a_byte_order_mark_before_a_comment_leaves_the_separator_to_the_header() {
        for sep in [",", ";", "\t"] {
            let (_d, p) =
                table(&format!("\u{feff}# exported\nt [s]{sep}x [um]{sep}f [mN]\n0{sep}1{sep}2\n1{sep}3{sep}4\n"));
            let t = read(&p).unwrap_or_else(|e| panic!("{sep:?}: {e:#}"));
            assert_eq!(t.t, vec![0.0, 1.0], "{sep:?}");
            assert!((t.f[1] - 4e-3).abs() < 1e-15, "{sep:?}");
        }
    }

    /// A table saved in Latin-1 (an instrument's µ as byte 0xB5) is read, in each separator's way (it
    /// was refused as "not valid UTF-8", with no line).
    #[test]
    fn a_table_saved_in_latin_1_is_read_with_its_micro_sign() {
        for sep in [b",".as_slice(), b"\t", b"   "] {
            let mut bytes = b"# \xB5 in Latin-1\nt [s]".to_vec();
            for cell in [b"x [\xB5m]".as_slice(), b"f [mN]"] {
                bytes.extend_from_slice(sep);
                bytes.extend_from_slice(cell);
            }
            bytes.extend_from_slice(b"\n");
            for row in [[b"0".as_slice(), b"1", b"2"], [b"1", b"3", b"4"]] {
                bytes.extend_from_slice(&row.join(sep));
                bytes.push(b'\n');
            }
            let dir = tempfile::tempdir().unwrap();
            let path = dir.path().join("latin1.csv");
            std::fs::write(&path, &bytes).unwrap();
            let t = read(&path).unwrap_or_else(|e| panic!("{sep:?}: {e:#}"));
            assert!((t.depth[1] - 3e-6).abs() < 1e-18 && (t.f[1] - 4e-3).abs() < 1e-15, "{sep:?}: {t:?}");
        }
    }
}
