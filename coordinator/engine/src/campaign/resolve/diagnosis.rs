//! How `calib diagnose` treats the campaign: its `[diagnosis]` section.

use super::super::spec::DiagnosisSection;
use super::super::{CampaignError, DiagnosisSettings};
use super::Locator;
use crate::limits;
use calib_model::validate;
use calib_model::ModelInfo;
use toml::Spanned;

pub(super) fn resolve_diagnosis(
    section: Option<Spanned<DiagnosisSection>>,
    info: &ModelInfo,
    at: &Locator,
) -> Result<DiagnosisSettings, CampaignError> {
    let mut diagnosis = DiagnosisSettings {
        holdout: None,
        refit: 3,
        candidates: None,
    };
    let Some(d) = section else {
        return Ok(diagnosis);
    };
    let span = d.span();
    let d = d.into_inner();
    match (d.holdout_start, d.holdout_stop) {
        (None, None) => {}
        (Some(a), Some(b)) if a.is_finite() && b.is_finite() && 0.0 <= a && a < b => {
            diagnosis.holdout = Some((a, b));
        }
        (Some(a), Some(b)) => {
            return at.error(
                span,
                "diagnosis.holdout_start",
                format!("the held-out window [{a}, {b}] must have 0 ≤ start < stop"),
            );
        }
        _ => {
            return at.error(
                span,
                "diagnosis.holdout_start",
                "give both holdout_start and holdout_stop, or neither".into(),
            );
        }
    }
    if let Some(refit) = d.refit {
        if refit == 0 {
            return at.error(span, "diagnosis.refit", "must be at least 1".into());
        }
        if let Err(e) = limits::at_most(refit, limits::MAX_REFIT, "refitted candidates") {
            return at.error(span, "diagnosis.refit", e);
        }
        diagnosis.refit = refit;
    }
    if let Some(candidates) = d.candidates {
        if let Err(e) = limits::at_most(candidates.len(), limits::MAX_CANDIDATES, "candidates") {
            return at.error(span, "diagnosis.candidates", e);
        }
        if let Some(e) = candidates
            .iter()
            .find_map(|c| validate::effect(info, c).err())
        {
            return at.error(span, "diagnosis.candidates", e.message);
        }
        diagnosis.candidates = Some(candidates);
    }
    Ok(diagnosis)
}
