//! Global sensitivity of the objective, and of each output's contribution to it, to the free
//! parameters over their bounds (on their search scale): Morris elementary effects (μ*, σ)
//! and Sobol first-order and total indices.
//!
//! Every sample set (the Morris trajectories, the Saltelli design) is one batch through the
//! store-backed evaluator `calib calibrate` uses, so it spreads over the workers, lands in
//! the evaluation store and is answered from it when asked again. A failed simulation has no
//! quantity to analyse: the Morris effects that need the point, and the Sobol base samples
//! with a failed point, are left out and counted.

pub mod local;
pub mod report;
pub mod sampling;

use calib_engine::calibration::load_measurement;
use calib_engine::campaign::{Campaign, Scale};
use calib_engine::error::{Error, Result};
use calib_engine::evaluator::{CacheStats, Evaluator};
use calib_engine::limits::MAX_SENSITIVITY_SAMPLES;
use calib_engine::objective::{Evaluation, Objective};
use calib_engine::optim::space::UnitBox;
use calib_engine::store::{encoding, Store, Stored, StoredEvaluator};
use sampling::{MorrisEffects, SobolIndices};

/// The total index on the objective at and above which a parameter is influential.
pub const INFLUENTIAL_TOTAL: f64 = 0.01;

/// [`Sensitivity::crowded_at_the_bottom`]: a nominal value in this bottom fraction of linear
/// bounds...
pub const CROWDED_FRACTION: f64 = 0.05;
/// ...and at least this many decades below the upper bound.
pub const CROWDED_DECADES: i32 = 1;

/// Which analyses to run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Methods {
    Morris,
    Sobol,
    /// Both (the default).
    #[default]
    Both,
}

impl Methods {
    fn morris(self) -> bool {
        self != Methods::Sobol
    }

    fn sobol(self) -> bool {
        self != Methods::Morris
    }
}

/// How to sample.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Settings {
    pub methods: Methods,
    /// Sobol: base samples of the Saltelli design (`samples · (parameters + 2)`
    /// evaluations). Morris: trajectories (`samples · (parameters + 1)` evaluations).
    pub samples: usize,
    pub seed: u64,
}

impl Settings {
    /// The settings held to their limits before a design is drawn: at least 2 samples, at
    /// most [`MAX_SENSITIVITY_SAMPLES`].
    pub fn check(&self) -> Result<()> {
        if self.samples < 2 || self.samples > MAX_SENSITIVITY_SAMPLES {
            return Err(Error::InvalidRequest(format!(
                "samples: {} is not between 2 and {MAX_SENSITIVITY_SAMPLES}",
                self.samples
            )));
        }
        Ok(())
    }
}

/// Default base samples (Sobol) and trajectories (Morris).
pub const DEFAULT_SAMPLES: usize = 128;

/// One analysed quantity: the objective or one output's weighted contribution.
#[derive(Debug, Clone, PartialEq)]
pub struct Quantity {
    /// `objective`, or the output's model name.
    pub name: String,
    pub morris: Option<MorrisEffects>,
    pub sobol: Option<SobolIndices>,
}

/// What a sensitivity analysis found.
#[derive(Debug, Clone)]
pub struct Sensitivity {
    pub campaign: String,
    pub parameters: Vec<String>,
    pub scales: Vec<Scale>,
    pub bounds: Vec<(f64, f64)>,
    /// Each free parameter's nominal value.
    pub nominals: Vec<f64>,
    pub settings: Settings,
    /// The objective first, then one per output in campaign order.
    pub quantities: Vec<Quantity>,
    /// Points evaluated per method, and how many of them failed.
    pub morris_points: usize,
    pub morris_failed: usize,
    pub sobol_points: usize,
    pub sobol_failed: usize,
    /// Sobol base samples left out because one of their points failed.
    pub sobol_excluded: usize,
    pub stats: CacheStats,
    /// Local sensitivities at a calibration's best point, when there is one
    /// ([`local::at_fit`]).
    pub at_fit: Option<local::AtFit>,
}

impl Sensitivity {
    /// Whether parameter `i` matters on quantity `q` (the objective, 0, or one output's
    /// contribution): its total index there is at least [`INFLUENTIAL_TOTAL`] (or, with
    /// Morris alone, its μ* there is at least that fraction of the largest μ*).
    pub fn influential_on(&self, q: usize, i: usize) -> bool {
        let quantity = &self.quantities[q];
        if let Some(s) = &quantity.sobol {
            return s.total[i] >= INFLUENTIAL_TOTAL;
        }
        let m = quantity.morris.as_ref().expect("one method ran");
        let largest = m.mu_star.iter().copied().fold(0.0, f64::max);
        largest > 0.0 && m.mu_star[i] >= INFLUENTIAL_TOTAL * largest
    }

    /// Whether parameter `i` matters: on the objective or on any output's contribution. The
    /// objective over the whole box can be dominated by one output's errors far from any
    /// fit (the heat exchanger's pressure drop), hiding a parameter that carries another
    /// output: holding it fixed would lose that output's fit.
    pub fn influential(&self, i: usize) -> bool {
        (0..self.quantities.len()).any(|q| self.influential_on(q, i))
    }

    /// The output (quantity index ≥ 1) that keeps parameter `i` in although it is not
    /// influential on the objective: the one on which its index is largest among those it
    /// is influential on. `None` when it is influential on the objective or on nothing.
    pub fn kept_for(&self, i: usize) -> Option<usize> {
        if self.influential_on(0, i) {
            return None;
        }
        (1..self.quantities.len())
            .filter(|&q| self.influential_on(q, i))
            .max_by(|&a, &b| self.score(a, i).total_cmp(&self.score(b, i)))
    }

    /// Parameter `i`'s index on quantity `q`: the total index, else μ* relative to the
    /// largest μ* there.
    fn score(&self, q: usize, i: usize) -> f64 {
        let quantity = &self.quantities[q];
        if let Some(s) = &quantity.sobol {
            return s.total[i];
        }
        let m = quantity.morris.as_ref().expect("one method ran");
        let largest = m.mu_star.iter().copied().fold(0.0, f64::max);
        if largest > 0.0 {
            m.mu_star[i] / largest
        } else {
            0.0
        }
    }

    /// The parameters that can be held fixed (not influential on the objective nor on any
    /// output, over the bounds nor, when there are local sensitivities, at the fit), in
    /// campaign order.
    pub fn fixable(&self) -> Vec<&str> {
        (0..self.parameters.len())
            .filter(|&i| self.is_fixable(i))
            .map(|i| self.parameters[i].as_str())
            .collect()
    }

    fn is_fixable(&self, i: usize) -> bool {
        !self.influential(i) && !self.influential_at_fit(i)
    }

    /// The most influential parameter on quantity `q` (largest total index, else μ*).
    pub fn most_influential(&self, q: usize) -> usize {
        let quantity = &self.quantities[q];
        let scores = match (&quantity.sobol, &quantity.morris) {
            (Some(s), _) => &s.total,
            (None, Some(m)) => &m.mu_star,
            (None, None) => unreachable!("one method ran"),
        };
        (0..scores.len())
            .max_by(|&a, &b| scores[a].total_cmp(&scores[b]))
            .unwrap_or(0)
    }

    /// Whether parameter `i` is searched on a linear scale over bounds so wide that its
    /// nominal value sits in the bottom [`CROWDED_FRACTION`] of them, at least
    /// [`CROWDED_DECADES`] decades below the upper bound: the samples then fall almost all
    /// far above the values that matter, and a small index may only say so.
    pub fn crowded_at_the_bottom(&self, i: usize) -> bool {
        let (min, max) = self.bounds[i];
        let nominal = self.nominals[i];
        self.scales[i] == Scale::Lin
            && min >= 0.0
            && nominal > 0.0
            && nominal - min < CROWDED_FRACTION * (max - min)
            && max >= 10f64.powi(CROWDED_DECADES) * nominal
    }

    /// The sentence naming the parameters that can be held fixed, with a caution for those
    /// whose bounds hide their small values (see [`Self::crowded_at_the_bottom`]).
    pub fn conclusion(&self) -> String {
        let mut sentence = self.fixable_sentence();
        for i in (0..self.parameters.len()).filter(|&i| self.is_fixable(i)) {
            if self.crowded_at_the_bottom(i) {
                let (min, max) = self.bounds[i];
                sentence.push_str(&format!(
                    " Caution: {name}'s bounds [{min}, {max}] span decades on a linear scale, \
                     so values near its nominal {nominal} are hardly sampled; analyse it on \
                     scale = \"log10\" (min above 0) before holding it fixed.",
                    name = self.parameters[i],
                    nominal = self.nominals[i],
                ));
            }
        }
        sentence
    }

    fn fixable_sentence(&self) -> String {
        let fixable = self.fixable();
        let sobol = self.quantities[0].sobol.is_some();
        let index = if sobol { "total index" } else { "μ*" };
        let below = if sobol {
            format!("below {INFLUENTIAL_TOTAL}")
        } else {
            format!("below {INFLUENTIAL_TOTAL} of the largest")
        };
        let outputs = if self.quantities.len() > 1 {
            " and on every output's contribution"
        } else {
            ""
        };
        let at_fit = if self.at_fit.is_some() {
            format!(" and a local index at the fit below {INFLUENTIAL_TOTAL}")
        } else {
            String::new()
        };
        let rule = format!("{index} on the objective{outputs} {below}");
        let mut sentence = match fixable.len() {
            0 => format!("No parameter can be held fixed: none has a {rule}{at_fit}."),
            1 => format!(
                "{} can be held fixed: its {rule} over the bounds{at_fit}.",
                fixable[0]
            ),
            _ => format!(
                "{} can be held fixed: each has a {rule} over the bounds{at_fit}.",
                fixable.join(", ")
            ),
        };
        for i in 0..self.parameters.len() {
            if let Some(q) = self.kept_for(i) {
                let (on_objective, there) = (self.score(0, i), self.score(q, i));
                let relative = if sobol { "" } else { " of the largest" };
                sentence.push_str(&format!(
                    " {name} is kept for {output}: its {index} is {there:.3}{relative} there, \
                     {on_objective:.3}{relative} on the objective; holding it fixed would lose \
                     that output's fit.",
                    name = self.parameters[i],
                    output = self.quantities[q].name,
                ));
            }
        }
        sentence.push_str(&self.kept_at_fit_sentences());
        sentence
    }
}

/// The analysed quantities of one evaluation: the objective, then each output's weighted
/// squared error `k_i · SSE_i`; `None` for a failed simulation.
fn quantities(objective: &Objective, e: &Evaluation) -> Option<Vec<f64>> {
    if e.failure.is_some() {
        return None;
    }
    let mut q = vec![e.objective];
    let weights = objective.experiments().flat_map(|part| &part.weights);
    q.extend(e.sse.iter().zip(weights).map(|(s, k)| s * k));
    Some(q)
}

/// Points a design is evaluated in, at most: large enough to fill many workers, small enough
/// to report progress while a large design runs. (Every point is independent, so slicing
/// changes no number.)
pub const SLICE_POINTS: usize = 256;

/// The evaluations an analysis of `dim` free parameters needs.
pub fn planned(dim: usize, settings: Settings) -> usize {
    let mut n = 0;
    if settings.methods.morris() {
        n += settings.samples * (dim + 1);
    }
    if settings.methods.sobol() {
        n += settings.samples * (dim + 2);
    }
    n
}

/// The request's own limits: a free parameter at least, settings in range, a Saltelli
/// design within its size.
fn check(dim: usize, settings: &Settings) -> Result<()> {
    if dim == 0 {
        return Err(Error::InvalidRequest(
            "the campaign has no free parameter to analyse".into(),
        ));
    }

    settings.check()?;
    if settings.methods.sobol()
        && (settings.samples > sampling::SALTELLI_MAX_SAMPLES
            || 2 * dim > sampling::SALTELLI_MAX_DIMENSIONS)
    {
        return Err(Error::InvalidRequest(format!(
            "Sobol indices take at most {} samples and {} parameters",
            sampling::SALTELLI_MAX_SAMPLES,
            sampling::SALTELLI_MAX_DIMENSIONS / 2
        )));
    }
    Ok(())
}

/// The result before any design is evaluated: the parameters, and the quantities analysed
/// (the objective, then each compared series, named after its output and its experiment when
/// there are several).
fn empty_result(campaign: &Campaign, objective: &Objective, settings: Settings) -> Sensitivity {
    let mut names = vec!["objective".to_string()];
    // Each compared series, named after its output (and its experiment when there are
    // several).
    let several = !campaign.more.is_empty() || !campaign.experiment.is_empty();
    let info = campaign.model.info();
    for part in objective.experiments() {
        for &o in &part.outputs {
            let output = &info.outputs[o].name;
            names.push(if several {
                format!("{}: {output}", part.name)
            } else {
                output.clone()
            });
        }
    }
    Sensitivity {
        campaign: campaign.name.clone(),
        parameters: campaign.free.iter().map(|p| p.name.clone()).collect(),
        scales: campaign.free.iter().map(|p| p.scale).collect(),
        bounds: campaign.free.iter().map(|p| (p.min, p.max)).collect(),
        nominals: campaign.free.iter().map(|p| p.nominal).collect(),
        settings,
        quantities: names
            .into_iter()
            .map(|name| Quantity {
                name,
                morris: None,
                sobol: None,
            })
            .collect(),
        morris_points: 0,
        morris_failed: 0,
        sobol_points: 0,
        sobol_failed: 0,
        sobol_excluded: 0,
        stats: CacheStats::default(),
        at_fit: None,
    }
}

/// Analyse `campaign`'s sensitivities, simulating through `evaluator` behind `store`.
pub fn analyse<E: Evaluator>(
    campaign: &Campaign,
    evaluator: E,
    store: &dyn Store,
    settings: Settings,
) -> Result<Sensitivity> {
    analyse_reporting(campaign, evaluator, store, settings, &|_, _| {})
}

/// [`analyse`], calling `progress(evaluated, planned)` after every slice of the designs.
pub fn analyse_reporting<E: Evaluator>(
    campaign: &Campaign,
    evaluator: E,
    store: &dyn Store,
    settings: Settings,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<Sensitivity> {
    StoredEvaluator::with(evaluator, store, |stored| {
        analyse_through(campaign, stored, store, settings, progress)
    })
}

/// [`analyse_reporting`] through `evaluator`: one of a dispatcher over `store` that others
/// share (a coordinator's).
pub fn analyse_through<S: Stored>(
    campaign: &Campaign,
    evaluator: &S,
    store: &dyn Store,
    settings: Settings,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<Sensitivity> {
    let dim = campaign.free.len();
    check(dim, &settings)?;
    let measurement = load_measurement(campaign)?;
    let objective = Objective::new(campaign, &measurement)?;
    let dataset = measurement.content_hash();
    if store.dataset(&dataset)?.is_none() {
        store.put_dataset(&dataset, &encoding::encode_measurement(&measurement))?;
    }
    let space = UnitBox::new(&campaign.free);
    let outputs = objective.series_count();
    let total = planned(dim, settings);
    let done = std::cell::Cell::new(0);
    progress(0, total);
    let evaluate = |unit: &[Vec<f64>]| -> Result<Vec<Option<Vec<f64>>>> {
        let mut values = Vec::with_capacity(unit.len());
        for slice in unit.chunks(SLICE_POINTS) {
            let physical: Vec<Vec<f64>> = slice.iter().map(|u| space.to_physical(u)).collect();
            let evaluations = evaluator.evaluate(&objective, &physical)?;
            if let Some(e) = evaluator.error() {
                return Err(e.into());
            }
            values.extend(evaluations.iter().map(|e| quantities(&objective, e)));
            done.set(done.get() + slice.len());
            progress(done.get(), total);
        }
        Ok(values)
    };
    let column = |values: &[Option<Vec<f64>>], q: usize| -> Vec<Option<f64>> {
        values.iter().map(|v| v.as_ref().map(|v| v[q])).collect()
    };
    let mut result = empty_result(campaign, &objective, settings);
    if settings.methods.morris() {
        let design = sampling::morris_design(dim, settings.samples, settings.seed);
        let values = evaluate(&design)?;
        result.morris_points = design.len();
        result.morris_failed = values.iter().filter(|v| v.is_none()).count();
        for q in 0..=outputs {
            result.quantities[q].morris =
                Some(sampling::morris_effects(&design, &column(&values, q), dim));
        }
    }
    if settings.methods.sobol() {
        let n = settings.samples;
        let design = sampling::saltelli_design(dim, n, settings.seed);
        let values = evaluate(&design)?;
        result.sobol_points = design.len();
        result.sobol_failed = values.iter().filter(|v| v.is_none()).count();
        result.sobol_excluded = (0..n)
            .filter(|&j| (0..dim + 2).any(|block| values[block * n + j].is_none()))
            .count();
        for q in 0..=outputs {
            result.quantities[q].sobol = Some(sampling::sobol_indices(
                &column(&values, q),
                dim,
                n,
                settings.seed,
            ));
        }
    }
    result.stats = evaluator.stats();
    Ok(result)
}
