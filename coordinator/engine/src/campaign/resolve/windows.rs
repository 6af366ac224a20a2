//! The fitted intervals of a record and the end of its simulated horizon.

use super::super::spec::WindowSection;
use super::super::CampaignError;
use super::Locator;
use crate::limits;
use calib_model::validate;
use toml::Spanned;

/// The fitted intervals: one `window` table or a `windows` list of disjoint `[start, stop]`
/// pairs in increasing order (`prefix` places the keys, e.g. "experiments[1] (swing).").
pub(super) fn resolve_windows(
    window: Option<Spanned<WindowSection>>,
    windows: Option<Spanned<Vec<[f64; 2]>>>,
    prefix: &str,
    at: &Locator,
) -> Result<Vec<(f64, f64)>, CampaignError> {
    let check = |start: f64, stop: f64, span, field: &str| {
        if !start.is_finite() || !stop.is_finite() || start < 0.0 || start >= stop {
            return at.error(
                span,
                field,
                format!("start ({start}) must be ≥ 0 and below stop ({stop})"),
            );
        }
        Ok(())
    };
    match (window, windows) {
        (Some(w), None) => {
            let (start, stop) = (w.get_ref().start, w.get_ref().stop);
            check(start, stop, w.span(), &format!("{prefix}window"))?;
            Ok(vec![(start, stop)])
        }
        (None, Some(list)) => {
            let field = format!("{prefix}windows");
            let span = list.span();
            let list = list.into_inner();
            if list.is_empty() {
                return at.error(span, &field, "lists no interval".into());
            }
            if let Err(e) = limits::at_most(list.len(), limits::MAX_WINDOWS, "fitted intervals") {
                return at.error(span, &field, e);
            }
            let mut out: Vec<(f64, f64)> = Vec::with_capacity(list.len());
            for (k, [start, stop]) in list.into_iter().enumerate() {
                check(start, stop, span.clone(), &format!("{field}[{k}]"))?;
                if let Some(&(_, before)) = out.last() {
                    if start < before {
                        return at.error(
                            span,
                            &format!("{field}[{k}]"),
                            format!(
                                "[{start}, {stop}] starts before the previous interval ends \
                                 ({before}): list disjoint intervals in time order"
                            ),
                        );
                    }
                }
                out.push((start, stop));
            }
            Ok(out)
        }
        (Some(w), Some(_)) => at.error(
            w.span(),
            &format!("{prefix}window"),
            "give `window` or `windows`, not both".into(),
        ),
        (None, None) => at.unlocated(
            &format!("{prefix}window"),
            "missing [window] with `start` and `stop` (seconds), or `windows = [[start, stop], \
             ...]`",
        ),
    }
}

pub(super) fn resolve_stop_time(
    stop_time: Option<&Spanned<f64>>,
    field: &str,
    section_span: std::ops::Range<usize>,
    window_stop: f64,
    at: &Locator,
) -> Result<f64, CampaignError> {
    let stop_time = match stop_time {
        Some(t) => {
            let v = *t.get_ref();
            if !v.is_finite() || v < window_stop {
                return at.error(
                    t.span(),
                    field,
                    format!("{v} must be ≥ the window's stop ({window_stop})"),
                );
            }
            v
        }
        None => window_stop,
    };
    if let Err(e) = validate::stop_time(stop_time) {
        return at.error(section_span, field, e.message);
    }
    Ok(stop_time)
}
