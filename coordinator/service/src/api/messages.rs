//! The domain's snapshots as the messages the service answers: a campaign's state, a
//! diagnosis's, an analysis's, an uploaded FMU.

use super::{discovery, result};
use crate::hosting::analyses::{AnalysisReport, AnalysisSnapshot};
use crate::hosting::diagnoses::DiagnosisSnapshot;
use crate::hosting::fmus::FmuInfo;
use crate::hosting::{Phase, Snapshot};
use calib_analysis::report;
use calib_proto::v1 as pb;
use calib_worker::service::simulator::describe;

fn phase(p: Phase) -> pb::CampaignPhase {
    match p {
        Phase::Running => pb::CampaignPhase::Running,
        Phase::Finished => pb::CampaignPhase::Finished,
        Phase::Failed => pb::CampaignPhase::Failed,
        Phase::Cancelled => pb::CampaignPhase::Cancelled,
    }
}

pub(super) fn state(s: &Snapshot) -> pb::CampaignState {
    let (runs, best_parameters) = match &s.result {
        Some(outcome) => (
            result::run_messages(outcome),
            outcome
                .best
                .parameters
                .iter()
                .map(|(k, v)| (k.to_string(), *v))
                .collect(),
        ),
        None => {
            let rows = report::runs::rows_so_far(&s.runs, &s.free);
            let best = report::runs::best_parameters(&rows).into_iter().collect();
            (rows.into_iter().map(result::row_message).collect(), best)
        }
    };
    let at_best = runs.iter().filter(|r| r.at_best).count() as u64;
    let rounds = match &s.result {
        Some(outcome) => outcome.rounds,
        None => {
            let each: Vec<usize> = runs.iter().map(|r| r.rounds as usize).collect();
            calib_engine::optim::multistart::plan_rounds(&each) as u64
        }
    };
    pb::CampaignState {
        rounds,
        campaign: s
            .message
            .clone()
            .and_then(|m| serde_json::from_value(m).ok()),
        history: s
            .history
            .points()
            .iter()
            .map(|p| pb::ProgressPoint {
                evaluations: p.evaluations,
                run_best: p
                    .run_best
                    .iter()
                    .map(|v| v.unwrap_or(f64::INFINITY))
                    .collect(),
            })
            .collect(),
        runs_at_best: Some(pb::RunsAtBest {
            count: at_best,
            of: runs.len() as u64,
            tolerance: calib_engine::evidence::BEST_TOLERANCE,
        }),
        runs,
        simulated: s.result.as_ref().map(|o| o.simulated).unwrap_or_default(),
        from_store: s
            .result
            .as_ref()
            .map(|o| o.from_store())
            .unwrap_or_default(),
        best_parameters,
        id: s.id.clone(),
        name: s.name.clone(),
        phase: phase(s.phase).into(),
        evaluations: s.evaluations,
        run_best: s.run_best.clone(),
        best_objective: s.best_objective,
        failure: s.failure.clone().unwrap_or_default(),
        result_json: s
            .result
            .as_ref()
            .map(|o| o.to_json_text())
            .unwrap_or_default(),
        result: s.result.as_ref().map(result::result_message),
        plots: s.plots.iter().cloned().collect(),
    }
}

/// The answer of `UploadFmu` and `GetFmu`.
pub(super) fn fmu_message(info: &FmuInfo) -> pb::Fmu {
    pb::Fmu {
        id: info.id.clone(),
        file_name: info.file_name.clone(),
        size: info.size,
        models: info.models.iter().map(|m| describe(*m)).collect(),
    }
}

pub(super) fn diagnosis_state(s: &DiagnosisSnapshot) -> pb::DiagnosisState {
    pb::DiagnosisState {
        campaign_id: s.campaign_id.clone(),
        phase: phase(s.phase).into(),
        evaluations: s.evaluations,
        failure: s.failure.clone().unwrap_or_default(),
        report_json: pretty_json(s.report.as_ref()),
        files: s.files.iter().cloned().collect(),
        found_outside_the_library: s.found.as_deref().map(discovery::found_message),
        report: s.report.as_ref().and_then(typed),
    }
}

pub(super) fn analysis_state(s: &AnalysisSnapshot) -> pb::AnalysisState {
    pb::AnalysisState {
        id: s.id.clone(),
        phase: phase(s.phase).into(),
        evaluations: s.evaluations,
        planned: s.planned,
        failure: s.failure.clone().unwrap_or_default(),
        report_json: pretty_json(s.report.as_ref().map(AnalysisReport::json)),
        conclusion: s.conclusion.clone(),
        files: s.files.iter().cloned().collect(),
        sensitivity: match &s.report {
            Some(AnalysisReport::Sensitivity(json)) => typed(json),
            _ => None,
        },
        profile: match &s.report {
            Some(AnalysisReport::Profile(json)) => typed(json),
            _ => None,
        },
    }
}

/// A report's typed message, read from the JSON of its file: the messages hold the files'
/// names and values (`calibration.proto`, "The reports of the analyses, typed"), which
/// the tests of each report hold field for field. A report the message cannot hold is a
/// bug: logged, and left to `report_json`.
fn typed<T: serde::de::DeserializeOwned>(json: &serde_json::Value) -> Option<T> {
    T::deserialize(json)
        .map_err(|e| tracing::error!(error = %e, "a report does not fit its typed message"))
        .ok()
}

/// A report as the indented JSON of the `report_json` fields; empty before there is one.
fn pretty_json<T: serde::Serialize>(report: Option<&T>) -> String {
    report
        .map(|r| serde_json::to_string_pretty(r).expect("plain data"))
        .unwrap_or_default()
}
