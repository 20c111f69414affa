//! The base law's kind re-chosen before effects are added: a wrong baseline is fixed, not patched.
//!
//! A law of the wrong damping form — Hunt–Crossley's λ z^{3/2} ż given for a surface whose damping goes
//! as z^{1/2} ż (Azad–Featherstone), or a linear spring given for a Hertzian one — leaves a residual that
//! follows the motion. The effects of the library would patch it with a stand-in (a relaxation at the
//! grid's fast edge, a hysteresis) or leave it `unexplained`; neither is the finding, which is the kind.
//!
//! So before the rounds, every other kind of [`Kind::CANDIDATES`] is refitted on the record exactly as
//! the given law is ([`refit_law`]: k, λ and the surface position, interleaved folds held out). A kind whose
//! held-out MSE is below the given law's by [`Options::min_gain`] is a rival, and the whole workflow runs
//! on it as well ([`crate::analyse`]); it replaces the given kind only where its final model also fits the
//! whole record better by that margin and is not itself beaten by the baseline as given. Requiring both
//! keeps a kind that merely absorbs part of a real effect (a damping form that mimics part of a
//! relaxation's lag fits the baseline better but, once the relaxation is named on the right kind, fits
//! worse) from displacing the law identify chose. The report says so in
//! [`crate::Report::law_rechosen`].
//!
//! A given law of [`Kind::General`] exponents (an estimated exponent) or of [`Kind::HertzWalton`] (a
//! sphere's law with its tangential part) is the user's choice of form and is not re-chosen.

use softcontact_contact::{ContactModel, Kind};

use crate::analysis::refit_law;
use crate::fit::Data;
use crate::{DiscrepancyError, Options, Series, simulate, to_model};

/// A law of another kind that fits the record better than the given one before any effect.
pub(crate) struct Rival {
    /// The given model in the rival's kind and exponents, its k and λ refitted (and no effects).
    pub law: ContactModel,
    pub held_out_rms: f64,
}

/// The given law's held-out RMS after its refit, and the rivals, best first.
pub(crate) fn rivals(
    series: &Series,
    given: &ContactModel,
    options: &Options,
) -> Result<(f64, Vec<Rival>), DiscrepancyError> {
    if !Kind::CANDIDATES.contains(&given.kind) {
        return Ok((f64::NAN, vec![]));
    }
    // The law refitted as the analysis refits it: its held-out MSE and the law with the fitted k and λ.
    let refitted = |law: &ContactModel| -> Result<(f64, ContactModel), DiscrepancyError> {
        let data = Data::new(series, options.folds, options.tare_window, law);
        let (structure, _, fit) = refit_law(&data, law)?;
        Ok((fit.cv_mse, to_model(law, &data, &structure, &fit, &[])))
    };
    let (given_mse, _) = refitted(given)?;
    let mut out = vec![];
    for kind in Kind::CANDIDATES.into_iter().filter(|&k| k != given.kind) {
        let Some(exponents) = kind.exponents() else { continue };
        let (mse, law) = refitted(&ContactModel { kind, exponents, ..given.clone() })?;
        if mse.is_finite() && mse < given_mse * (1.0 - options.min_gain) && law.validate().is_ok() {
            out.push(Rival { law, held_out_rms: mse.sqrt() });
        }
    }
    out.sort_by(|a, b| a.held_out_rms.total_cmp(&b.held_out_rms));
    Ok((given_mse.sqrt(), out))
}

/// The RMS over every sample of the record, in contact or not, of `model` with the surface moved by
/// `shift`: how the final model, the model given and a rival kind's final model are compared (neither
/// model's surface decides which samples count).
pub(crate) fn whole_rms(series: &Series, model: &ContactModel, shift: f64) -> Result<f64, DiscrepancyError> {
    let predicted = simulate(model, &series.shifted(shift))?;
    let sum: f64 = predicted.iter().zip(&series.f).map(|(p, f)| (f - p).powi(2)).sum();
    Ok((sum / series.len() as f64).sqrt())
}
