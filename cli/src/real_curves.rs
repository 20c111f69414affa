//! `softcontact bench discrepancy --real DIR`: the discrepancy workflow on measured curves no one here
//! made (`data/afm`), each against what a person sees in it (`DIR/expected.json`, written before the
//! workflow ran on them). The table is committed in `docs/discrepancy-real.md`.

use std::collections::BTreeSet;
use std::path::Path;

use anyhow::Context;
use serde::Deserialize;
use serde_json::json;
use softcontact_discrepancy::Remaining;

use crate::discrepancy_cmd::{self, DiscrepancyArgs};
use crate::identify_cmd::IdentifyArgs;
use crate::table::si;

#[derive(Debug, Deserialize)]
struct Expected {
    curves: Vec<Curve>,
}

/// One curve's expected answer: every group must have one of its ids named; `outside` says an effect no
/// id of the library describes is there (so the answer must not be that nothing remains).
#[derive(Debug, Deserialize)]
struct Curve {
    file: String,
    named: Vec<Vec<String>>,
    outside: Option<String>,
}

/// A name beyond the expected is not held against a curve that expects an effect (a person does not see
/// an exponent), but it is against one where a person saw nothing of the library. The adhesion a person
/// saw was written among what lies outside the library, which had no adhesion then: named, it is seen.
///
/// Whether the id `named` answers the expected id `seen`: the same id, or the quasi-linear form of a
/// relaxation where a person saw a relaxation (the expected answers were written when the library had one
/// relaxation id; they do not move).
fn same_effect(named: &str, seen: &str) -> bool {
    named == seen || (seen == "viscoelastic_relaxation" && named == "quasi_linear_relaxation")
}

/// One curve's outcome.
#[derive(Debug, Clone, serde::Serialize)]
pub struct Outcome {
    pub file: String,
    pub expected: String,
    /// The workflow's answer: the ids named, or why it refused.
    pub answer: Result<Vec<String>, String>,
    pub remaining: Option<String>,
    pub baseline_rms: f64,
    pub final_rms: f64,
    pub noise_floor: f64,
    pub kept_baseline: bool,
    /// Every expected group has one of its ids named.
    pub named_as_expected: bool,
    /// Where something outside the library is there, the answer is not that nothing remains.
    pub outside_not_denied: bool,
    /// The final model fits no worse than the baseline.
    pub not_worse: bool,
    /// The ids named that no expected group lists: what the workflow saw and the person did not.
    pub beyond_expected: Vec<String>,
    /// The gap's shrink as a share of what the noise allows, (baseline − final) / (baseline − noise σ).
    pub shrink_of_ideal: f64,
    /// Where an unexplained residual is and its shape there.
    pub what_is_left: Option<String>,
}

/// Runs every curve of `dir/expected.json`.
pub fn run(dir: &Path) -> anyhow::Result<Vec<Outcome>> {
    let path = dir.join("expected.json");
    let text = std::fs::read_to_string(&path).with_context(|| format!("reading {}", path.display()))?;
    let expected: Expected = serde_json::from_str(&text).with_context(|| format!("{} is malformed", path.display()))?;
    let out = std::env::temp_dir().join(format!("softcontact-real-curves-{}", std::process::id()));
    let mut outcomes = Vec::new();
    for curve in &expected.curves {
        let args = DiscrepancyArgs {
            recording: IdentifyArgs {
                file: dir.join(&curve.file),
                json: None,
                normal: vec![0.0, 0.0, -1.0],
                onset: None,
                sample_period: None,
            },
            model: None,
            surface: None,
            out: out.clone(),
            loading_paths: false,
            arm: false,
            closed_loop: false,
        };
        let expected_text = if curve.named.is_empty() {
            "nothing of the library".to_string()
        } else {
            curve.named.iter().map(|g| g.join(" or ")).collect::<Vec<_>>().join(" and ")
        } + &curve.outside.as_ref().map_or(String::new(), |o| format!("; outside: {o}"));
        let outcome = match discrepancy_cmd::analyse_file(&args, false) {
            Ok(a) => {
                let r = &a.report;
                let names: BTreeSet<String> = r.effects.iter().map(|e| e.id.clone()).collect();
                let remaining = match r.remaining {
                    Remaining::None => "none",
                    Remaining::Unexplained => "unexplained",
                    Remaining::Ambiguous => "ambiguous",
                };
                Outcome {
                    file: curve.file.clone(),
                    expected: expected_text,
                    named_as_expected: curve
                        .named
                        .iter()
                        .all(|g| g.iter().any(|id| names.iter().any(|n| same_effect(n, id))))
                        && (!curve.named.is_empty() || names.is_empty()),
                    outside_not_denied: curve.outside.is_none() || r.remaining != Remaining::None,
                    not_worse: r.final_rms <= r.baseline.rms,
                    beyond_expected: names
                        .iter()
                        .filter(|n| !curve.named.iter().flatten().any(|id| same_effect(n, id)))
                        .filter(|n| {
                            !(*n == "adhesion" && curve.outside.as_deref().is_some_and(|o| o.contains("adhesion")))
                        })
                        .cloned()
                        .collect(),
                    shrink_of_ideal: (r.baseline.rms - r.final_rms) / (r.baseline.rms - r.noise_floor),
                    what_is_left: discrepancy_cmd::what_is_left(r),
                    answer: Ok(names.into_iter().collect()),
                    remaining: Some(remaining.into()),
                    baseline_rms: r.baseline.rms,
                    final_rms: r.final_rms,
                    noise_floor: r.noise_floor,
                    kept_baseline: r.kept_baseline,
                }
            }
            // A refusal names nothing and returns no model: right where nothing is expected.
            Err(e) => Outcome {
                file: curve.file.clone(),
                expected: expected_text,
                named_as_expected: curve.named.is_empty(),
                outside_not_denied: true,
                not_worse: true,
                beyond_expected: vec![],
                shrink_of_ideal: f64::NAN,
                what_is_left: None,
                answer: Err(format!("{e:#}")),
                remaining: None,
                baseline_rms: f64::NAN,
                final_rms: f64::NAN,
                noise_floor: f64::NAN,
                kept_baseline: false,
            },
        };
        outcomes.push(outcome);
    }
    let _ = std::fs::remove_dir_all(&out);
    Ok(outcomes)
}

/// The markdown table and its summary line.
pub fn print(outcomes: &[Outcome]) {
    println!(
        "| curve | expected | named | beyond the expected | remaining | RMS baseline → final | noise σ | shrink of the ideal | as expected |"
    );
    println!("|---|---|---|---|---|---|---|---|---|");
    let mut left = vec![];
    for o in outcomes {
        let answer = match &o.answer {
            Ok(names) if names.is_empty() => "—".to_string(),
            Ok(names) => names.join(", "),
            Err(e) => format!("refused: {}", e.split(':').next().unwrap_or(e)),
        };
        let verdict = match (o.named_as_expected, o.outside_not_denied, o.not_worse) {
            (true, true, true) => "yes".to_string(),
            (named, outside, worse) => {
                let mut why = vec![];
                if !named && o.expected.starts_with("nothing") {
                    why.push("named what a person did not see");
                } else if !named {
                    why.push("not named");
                }
                if !outside {
                    why.push("said nothing remains");
                }
                if !worse {
                    why.push("worse than the baseline");
                }
                format!("no: {}", why.join(", "))
            }
        };
        let (rms, noise, shrink) = if o.answer.is_ok() {
            (
                format!("{} → {}", si(o.baseline_rms, "N"), si(o.final_rms, "N")),
                si(o.noise_floor, "N"),
                format!("{:.0} %", 100.0 * o.shrink_of_ideal),
            )
        } else {
            ("—".into(), "—".into(), "—".into())
        };
        if let Some(l) = &o.what_is_left {
            left.push(format!("- {}: {l}", o.file));
        }
        let beyond = if o.beyond_expected.is_empty() { "—".to_string() } else { o.beyond_expected.join(", ") };
        println!(
            "| {} | {} | {answer} | {beyond} | {}{} | {rms} | {noise} | {shrink} | {verdict} |",
            o.file,
            o.expected,
            o.remaining.as_deref().unwrap_or("—"),
            if o.kept_baseline { " (baseline kept)" } else { "" },
        );
    }
    let count = |f: &dyn Fn(&Outcome) -> bool| outcomes.iter().filter(|o| f(o)).count();
    let with_effect = outcomes.iter().filter(|o| !o.expected.starts_with("nothing")).count();
    println!("\nWhat is left where the answer is `unexplained` (the phase with most of the remaining residual):\n");
    println!("{}", left.join("\n"));
    let named: Vec<f64> = outcomes
        .iter()
        .filter(|o| !o.expected.starts_with("nothing") && o.named_as_expected)
        .map(|o| o.shrink_of_ideal)
        .collect();
    println!(
        "\nReal curves answered as expected: {}/{}; expected library effect named: {}/{with_effect}, with a shrink of at least 60 % of the ideal on {} of them; named beyond what a person saw: {} curves; nothing-remains said where something outside the library is: {}; final model worse than the baseline: {}",
        count(&|o| o.named_as_expected && o.outside_not_denied && o.not_worse),
        outcomes.len(),
        named.len(),
        named.iter().filter(|&&s| s >= 0.6).count(),
        count(&|o| !o.beyond_expected.is_empty()),
        count(&|o| !o.outside_not_denied),
        count(&|o| !o.not_worse),
    );
}

pub fn to_json(outcomes: &[Outcome]) -> serde_json::Value {
    json!({ "real_curves": outcomes })
}
