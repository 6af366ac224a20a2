//! How the optimisers search: the `[search]` section held to its limits.

use super::super::spec::{default_max_evaluations, default_methods, default_starts, SearchSection};
use super::super::{CampaignError, Search};
use super::Locator;
use crate::limits;
use toml::Spanned;

pub(super) fn resolve_search(
    section: Option<Spanned<SearchSection>>,
    free: usize,
    at: &Locator,
) -> Result<Search, CampaignError> {
    let Some(s) = section else {
        return Ok(default_search());
    };
    let span = s.span();
    let s = s.into_inner();
    if s.methods.is_empty() {
        return at.error(span, "search.methods", "name at least one method".into());
    }
    if s.starts == 0 {
        return at.error(span, "search.starts", "must be at least 1".into());
    }
    for (field, value, limit, what) in [
        ("search.starts", s.starts, limits::MAX_STARTS, "starts"),
        (
            "search.max_evaluations",
            s.max_evaluations,
            limits::MAX_EVALUATIONS,
            "evaluations per run",
        ),
        (
            "search.screening",
            s.screening.unwrap_or(0),
            limits::MAX_SCREENING,
            "screening points",
        ),
    ] {
        if let Err(e) = limits::at_most(value, limit, what) {
            return at.error(span, field, e);
        }
    }
    if let Some(population) = s.cma_population {
        if population < 2 || population > s.max_evaluations {
            return at.error(
                span,
                "search.cma_population",
                format!(
                    "{population} must lie between 2 and max_evaluations ({})",
                    s.max_evaluations
                ),
            );
        }
    }
    if s.max_evaluations < 2 * (free + 1) {
        return at.error(
            span,
            "search.max_evaluations",
            format!("{} is too few for {free} parameters", s.max_evaluations),
        );
    }
    let mut methods = s.methods;
    let mut seen = Vec::new();
    methods.retain(|m| {
        let first = !seen.contains(m);
        seen.push(*m);
        first
    });
    Ok(Search {
        methods,
        starts: s.starts,
        max_evaluations: s.max_evaluations,
        seed: s.seed,
        screening: s.screening,
        cma_population: s.cma_population,
        extra_starts: Vec::new(),
        stall: None,
    })
}

/// The search of a campaign without a `[search]` section.
fn default_search() -> Search {
    Search {
        methods: default_methods(),
        starts: default_starts(),
        max_evaluations: default_max_evaluations(),
        seed: 0,
        screening: None,
        cma_population: None,
        extra_starts: Vec::new(),
        stall: None,
    }
}
