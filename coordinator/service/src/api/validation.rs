//! The checks of a campaign message made before any campaign file is written: its form on
//! its own, then what it maps onto each dataset it names (columns, windows).

use super::problem::Problem;
use crate::hosting::datasets::DatasetInfo;
use calib_proto::v1 as pb;
use tonic::Status;

/// Most column names a refusal lists.
const LISTED_COLUMNS: usize = 20;

/// What a campaign of one record maps onto its dataset.
pub(super) fn mapped_campaign(campaign: &pb::Campaign) -> Mapped<'_> {
    let mut windows = Vec::new();
    // A window of 0 to 0 is no window: the campaign's check names it missing.
    if campaign.window_start != 0.0 || campaign.window_stop != 0.0 {
        windows.push((
            "window_start".to_string(),
            "window_stop".to_string(),
            campaign.window_start,
            campaign.window_stop,
        ));
    }
    for (j, w) in campaign.windows.iter().enumerate() {
        windows.push((
            format!("windows[{j}].start"),
            format!("windows[{j}].stop"),
            w.start,
            w.stop,
        ));
    }
    Mapped {
        place: String::new(),
        outputs: &campaign.outputs,
        inputs: &campaign.inputs,
        windows,
    }
}

/// What experiment `k` of a campaign maps onto its dataset.
pub(super) fn mapped_experiment(campaign: &pb::Campaign, k: usize) -> Mapped<'_> {
    let e = &campaign.experiments[k];
    let place = format!("experiments[{k}].");
    Mapped {
        place: place.clone(),
        outputs: own_or(&e.outputs, &campaign.outputs),
        inputs: own_or(&e.inputs, &campaign.inputs),
        windows: e
            .windows
            .iter()
            .enumerate()
            .map(|(j, w)| {
                (
                    format!("{place}windows[{j}].start"),
                    format!("{place}windows[{j}].stop"),
                    w.start,
                    w.stop,
                )
            })
            .collect(),
    }
}

/// An experiment's own list, or the campaign's when it has none.
fn own_or<'a, T>(own: &'a [T], campaign: &'a [T]) -> &'a [T] {
    if own.is_empty() {
        campaign
    } else {
        own
    }
}

/// What a campaign (or one of its experiments) maps onto a dataset: `place` prefixes the
/// fields named (e.g. "experiments[1]."); each window is its start's and stop's fields and
/// values.
pub(super) struct Mapped<'a> {
    place: String,
    outputs: &'a [pb::Output],
    inputs: &'a [pb::Input],
    windows: Vec<(String, String, f64, f64)>,
}

/// What the form of a campaign states wrong on its own, before any dataset or model is
/// looked at: every such problem, each at its field.
pub(super) fn form_problems(c: &pb::Campaign) -> Vec<Problem> {
    let mut problems = Vec::new();
    if !c.experiments.is_empty() && !c.dataset_id.is_empty() {
        problems.push(Problem::new(
            "dataset_id",
            "with experiments, each experiment names its dataset; leave this one empty",
        ));
    }
    if let Some(search) = &c.search {
        if search.methods.is_empty() {
            problems.push(Problem::new("search.methods", "choose at least one method"));
        }
    }
    problems.extend(output_problems(c));
    problems.extend(parameter_problems(c));
    problems.extend(form_window_problems(c));
    problems
}

/// The outputs to compare: at least one (the campaign's, or each experiment's own), each
/// with its measured column chosen.
fn output_problems(c: &pb::Campaign) -> Vec<Problem> {
    let mut problems = Vec::new();
    let no_outputs = "choose at least one output to compare with the measurement";
    if c.experiments.is_empty() {
        if c.outputs.is_empty() {
            problems.push(Problem::new("outputs", no_outputs));
        }
    } else if c.outputs.is_empty() {
        for (k, e) in c.experiments.iter().enumerate() {
            if e.outputs.is_empty() {
                problems.push(Problem::new(
                    format!("experiments[{k}].outputs"),
                    no_outputs,
                ));
            }
        }
    }
    let outputs = c
        .outputs
        .iter()
        .enumerate()
        .map(|(i, o)| (String::new(), i, o));
    let own = c.experiments.iter().enumerate().flat_map(|(k, e)| {
        e.outputs
            .iter()
            .enumerate()
            .map(move |(i, o)| (format!("experiments[{k}]."), i, o))
    });
    for (place, i, o) in outputs.chain(own) {
        if o.measured.is_empty() {
            problems.push(Problem::new(
                format!("{place}outputs[{i}].measured"),
                "choose the measured column this output is compared with",
            ));
        }
    }
    problems
}

/// The parameters to calibrate: at least one (shared, an effect, or an experiment's own),
/// each with its bounds ([`bound_problems`]).
fn parameter_problems(c: &pb::Campaign) -> Vec<Problem> {
    let mut problems = Vec::new();
    let shared_free = !c.parameters.is_empty() || !c.effects.is_empty();
    let own_free = c.experiments.iter().any(|e| !e.parameters.is_empty());
    if !shared_free && !own_free {
        problems.push(Problem::new(
            "parameters",
            "choose at least one parameter to calibrate",
        ));
    }
    let lists = [
        (String::from("parameters"), &c.parameters),
        (String::from("effects"), &c.effects),
    ];
    let own = c
        .experiments
        .iter()
        .enumerate()
        .map(|(k, e)| (format!("experiments[{k}].parameters"), &e.parameters));
    for (list, parameters) in lists.into_iter().chain(own) {
        for (i, p) in parameters.iter().enumerate() {
            problems.extend(bound_problems(&format!("{list}[{i}]"), p));
        }
    }
    problems
}

/// The windows of the data to fit: the campaign's one window or several (not both), or
/// each experiment's; each on its own ([`window_problems`]).
fn form_window_problems(c: &pb::Campaign) -> Vec<Problem> {
    let mut problems = Vec::new();
    if c.experiments.is_empty() {
        let (start, stop) = (c.window_start, c.window_stop);
        if c.windows.is_empty() && start == 0.0 && stop == 0.0 {
            problems.push(Problem::new(
                "window_stop",
                "give the window of the data to fit: its start and its stop",
            ));
        } else if !c.windows.is_empty() && (start != 0.0 || stop != 0.0) {
            problems.push(Problem::new(
                "windows",
                "give one window or several windows, not both",
            ));
        } else if c.windows.is_empty() {
            problems.extend(window_problems("window_start", "window_stop", start, stop));
        }
        for (j, w) in c.windows.iter().enumerate() {
            problems.extend(window_problems(
                &format!("windows[{j}].start"),
                &format!("windows[{j}].stop"),
                w.start,
                w.stop,
            ));
        }
    } else {
        for (k, e) in c.experiments.iter().enumerate() {
            if e.windows.is_empty() {
                problems.push(Problem::new(
                    format!("experiments[{k}].windows"),
                    "give the window of the data to fit: its start and its stop",
                ));
            }
            for (j, w) in e.windows.iter().enumerate() {
                problems.extend(window_problems(
                    &format!("experiments[{k}].windows[{j}].start"),
                    &format!("experiments[{k}].windows[{j}].stop"),
                    w.start,
                    w.stop,
                ));
            }
        }
    }
    problems
}

/// A free parameter's bounds, start value and scale, at `field` ("parameters[0]").
fn bound_problems(field: &str, p: &pb::Parameter) -> Vec<Problem> {
    let mut problems = Vec::new();
    if !p.min.is_finite() {
        problems.push(Problem::new(format!("{field}.min"), "give a lower bound"));
    }
    if !p.max.is_finite() {
        problems.push(Problem::new(format!("{field}.max"), "give an upper bound"));
    }
    if !problems.is_empty() {
        return problems;
    }
    if p.min >= p.max {
        problems.push(Problem::new(
            format!("{field}.max"),
            format!(
                "the upper bound {} must be above the lower bound {}",
                p.max, p.min
            ),
        ));
        return problems;
    }
    if p.scale == "log10" && p.min <= 0.0 {
        problems.push(Problem::new(
            format!("{field}.min"),
            format!(
                "a log10 scale needs a lower bound above 0 (it is {}); use the lin scale to \
                 search from 0",
                p.min
            ),
        ));
    }
    if let Some(nominal) = p.nominal {
        if !nominal.is_finite() || nominal < p.min || nominal > p.max {
            problems.push(Problem::new(
                format!("{field}.nominal"),
                format!(
                    "the start value {nominal} lies outside the bounds [{}, {}]",
                    p.min, p.max
                ),
            ));
        }
    }
    problems
}

/// A window's start and stop on their own: finite, from 0 s, the stop after the start.
fn window_problems(start_field: &str, stop_field: &str, start: f64, stop: f64) -> Vec<Problem> {
    if !start.is_finite() || start < 0.0 {
        return vec![Problem::new(
            start_field,
            format!("the window starts at {start} s; it must start at 0 s or later"),
        )];
    }
    if !stop.is_finite() || stop <= start {
        return vec![Problem::new(
            stop_field,
            format!("the window must end after it starts ({start} s); it ends at {stop} s"),
        )];
    }
    Vec::new()
}

/// The fields mapped onto a dataset checked against it, before anything is parsed or run:
/// every mapped column is one of the dataset's, the windows lie inside its data. Every
/// problem found.
pub(super) fn dataset_problems(mapped: &Mapped, dataset: &DatasetInfo) -> Vec<Problem> {
    let mut problems = Vec::new();
    let columns = mapped
        .outputs
        .iter()
        .enumerate()
        .map(|(i, o)| (format!("outputs[{i}]"), &o.measured))
        .chain(
            mapped
                .inputs
                .iter()
                .enumerate()
                .map(|(i, input)| (format!("inputs[{i}]"), &input.measured)),
        );
    for (field, measured) in columns {
        // An empty choice is the form's problem, named there.
        if measured.is_empty() || dataset.columns.contains(measured) {
            continue;
        }
        let mut listed: Vec<String> = dataset
            .columns
            .iter()
            .take(LISTED_COLUMNS)
            .map(|c| format!("{c:?}"))
            .collect();
        if dataset.columns.len() > LISTED_COLUMNS {
            listed.push(format!("… ({} in all)", dataset.columns.len()));
        }
        problems.push(Problem::new(
            format!("{}{field}.measured", mapped.place),
            format!(
                "dataset {} has no column {measured:?}; its columns are: {}",
                dataset.file_name,
                listed.join(", ")
            ),
        ));
    }
    let (first, last) = (dataset.start_time, dataset.stop_time);
    let slack = 1e-9 * last.abs().max(1.0);
    let outside = |field: &str, value: f64| {
        Problem::new(
            field,
            format!(
                "{value} s lies outside the data of dataset {} (time runs from {first} to {last} \
                 s)",
                dataset.file_name
            ),
        )
    };
    for (start_field, stop_field, start, stop) in &mapped.windows {
        // A window wrong on its own is the form's problem, named there.
        if !window_problems(start_field, stop_field, *start, *stop).is_empty() {
            continue;
        }
        if *stop > last + slack {
            problems.push(outside(stop_field, *stop));
        }
        if *start < first - slack {
            problems.push(outside(start_field, *start));
        }
    }
    problems
}

/// [`dataset_problems`]' first, as the refusal of a request.
pub(super) fn check_against_dataset(mapped: &Mapped, dataset: &DatasetInfo) -> Result<(), Status> {
    match dataset_problems(mapped, dataset).first() {
        Some(problem) => Err(problem.status()),
        None => Ok(()),
    }
}
