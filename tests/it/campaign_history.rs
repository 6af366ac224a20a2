//! What a coordinator keeps of a campaign for a client that comes back to it (a reloaded
//! page, a link, another client): the Campaign message it was submitted with, its progress
//! history, one row per run named as plots name it, its counts as `calib calibrate`'s
//! summary tells them, and, for a campaign cancelled before its end, the best point found.
//! All of it from the store, so it outlives a restart of the coordinator.

use crate::common::cluster::*;
use crate::common::coordinator::Coordinator;
use crate::common::*;
use calib_proto::v1 as pb;
use calib_proto::v1::calibration_client::CalibrationClient;
use serde_json::Value;
use std::time::Duration;

/// What these tests ask of the coordinator, over gRPC.
impl Coordinator {
    fn grpc<T>(
        &self,
        call: impl AsyncFnOnce(
            CalibrationClient<tonic::transport::Channel>,
        ) -> Result<tonic::Response<T>, tonic::Status>,
    ) -> T {
        let url = self.url();
        self.runtime.block_on(async {
            let client = CalibrationClient::connect(url).await.unwrap();
            call(client).await.map(tonic::Response::into_inner).unwrap()
        })
    }

    fn upload(&self) -> pb::Dataset {
        let chunk = pb::DatasetChunk {
            file_name: "record.csv".into(),
            time_column: "time_s".into(),
            data: std::fs::read(repo().join("examples/data/furuta_clean.csv")).unwrap(),
        };
        self.grpc(async move |mut c| c.upload_dataset(tokio_stream::iter([chunk])).await)
    }

    fn submit(&self, campaign: pb::Campaign) -> String {
        let request = pb::SubmitCampaignRequest {
            campaign: Some(campaign),
            idempotency_key: String::new(),
        };
        let answer = self.grpc(async move |mut c| c.submit_campaign(request).await);
        assert!(answer.started);
        answer.id
    }

    fn state(&self, id: &str) -> pb::CampaignState {
        let id = id.to_string();
        self.grpc(async move |mut c| c.get_campaign(pb::GetCampaignRequest { id }).await)
    }

    fn await_phase(&self, id: &str, phase: pb::CampaignPhase) -> pb::CampaignState {
        await_condition("the campaign's phase", Duration::from_secs(600), || {
            self.state(id).phase() == phase
        });
        self.state(id)
    }
}

fn message(search: &str, dataset: &str) -> pb::Campaign {
    calib_service::api::spec::campaign_message(&clean_campaign(search), dataset).unwrap()
}

/// The history's points in order, each no further on than the state, the last its end.
fn check_history(s: &pb::CampaignState) {
    let h = &s.history;
    assert!(!h.is_empty() && h.len() <= 200, "{} points", h.len());
    assert!(
        h.windows(2).all(|w| w[0].evaluations < w[1].evaluations),
        "not increasing"
    );
    let last = h.last().unwrap();
    assert_eq!(last.evaluations, s.evaluations);
    assert_eq!(last.run_best.len(), s.runs.len());
    // Each run's best only falls, and ends at the run's objective.
    for (r, run) in s.runs.iter().enumerate() {
        let series: Vec<f64> = h
            .iter()
            .filter_map(|p| p.run_best.get(r).copied())
            .collect();
        assert!(series.windows(2).all(|w| w[1] <= w[0]), "{}", run.label);
        assert_eq!(series.last().copied(), Some(run.objective), "{}", run.label);
    }
}

#[test]
fn a_finished_campaigns_spec_history_and_runs_are_the_results_and_survive_a_restart() {
    let dir = tempfile::tempdir().unwrap();
    let cluster = TestCluster::start(1, 2);
    let search =
        "methods = [\"nelder-mead\", \"powell\"]\nstarts = 2\nmax_evaluations = 120\nseed = 1";
    let (campaign, id, before) = {
        let c = Coordinator::start(dir.path(), &cluster.urls());
        let dataset = c.upload();
        let campaign = message(search, &dataset.id);
        let id = c.submit(campaign.clone());
        let s = c.await_phase(&id, pb::CampaignPhase::Finished);
        (campaign, id, s)
    };
    // The spec: the very message submitted.
    assert_eq!(before.campaign.as_ref(), Some(&campaign));
    check_history(&before);
    // One row per run of result.json, field for field, named "<method> #<start>".
    let result: Value = serde_json::from_str(&before.result_json).unwrap();
    let runs = result["runs"].as_array().unwrap();
    assert_eq!(before.runs.len(), runs.len());
    assert_eq!(before.runs.len(), 4);
    for (row, run) in before.runs.iter().zip(runs) {
        assert_eq!(row.method, run["method"].as_str().unwrap());
        assert_eq!(row.start, run["start"].as_u64().unwrap());
        assert_eq!(row.label, format!("{} #{}", row.method, row.start));
        assert_eq!(row.evaluations, run["evaluations"].as_u64().unwrap());
        assert_eq!(row.iterations, run["iterations"].as_u64().unwrap());
        assert_eq!(row.termination, run["termination"].as_str().unwrap());
        assert_eq!(row.objective, run["objective"].as_f64().unwrap());
        for (name, value) in run["parameters"].as_object().unwrap() {
            assert_eq!(row.parameters[name], value.as_f64().unwrap(), "{name}");
        }
        assert_eq!(row.parameters.len(), 2);
    }
    let at_best = before.runs.iter().filter(|r| r.at_best).count() as u64;
    assert_eq!(at_best, result["runs_at_best"]["count"].as_u64().unwrap());
    // The counts as the summary tells them: they add up to the evaluations.
    assert_eq!(before.simulated, result["simulated"].as_u64().unwrap());
    assert_eq!(before.evaluations, result["evaluations"].as_u64().unwrap());
    assert_eq!(before.simulated + before.from_store, before.evaluations);
    for (name, value) in result["best"]["parameters"].as_object().unwrap() {
        assert_eq!(before.best_parameters[name], value.as_f64().unwrap());
    }

    // Another coordinator on the same store: the same campaign, history and runs.
    let c = Coordinator::start(dir.path(), &cluster.urls());
    let after = c.state(&id);
    assert_eq!(after.phase(), pb::CampaignPhase::Finished);
    assert_eq!(after.campaign, before.campaign);
    assert_eq!(after.history, before.history);
    assert_eq!(after.runs, before.runs);
    assert_eq!(after.evaluations, before.evaluations);
    assert_eq!(after.best_parameters, before.best_parameters);
}

#[test]
fn a_cancelled_campaign_keeps_its_best_point_so_far_and_its_history_across_a_restart() {
    let dir = tempfile::tempdir().unwrap();
    let cluster = TestCluster::start(1, 2);
    let search = "methods = [\"nelder-mead\"]\nstarts = 2\nmax_evaluations = 100000";
    let (id, before) = {
        let c = Coordinator::start(dir.path(), &cluster.urls());
        let dataset = c.upload();
        let id = c.submit(message(search, &dataset.id));
        await_condition("some evaluations", Duration::from_secs(300), || {
            let s = c.state(&id);
            s.evaluations >= 60
                && !s.runs.is_empty()
                && s.runs.iter().all(|r| r.objective.is_finite())
        });
        let running = c.state(&id);
        assert_eq!(running.phase(), pb::CampaignPhase::Running);
        assert!(!running.history.is_empty());
        assert!(running.runs.iter().all(|r| r.termination.is_empty()));
        {
            let id = id.clone();
            c.grpc(async move |mut client| {
                client
                    .cancel_campaign(pb::CancelCampaignRequest { id })
                    .await
            });
        }
        (id.clone(), c.await_phase(&id, pb::CampaignPhase::Cancelled))
    };
    assert!(before.result_json.is_empty());
    check_history(&before);
    // The best point: the parameters of the run with the lowest objective, inside the
    // bounds searched.
    let best = before
        .runs
        .iter()
        .min_by(|a, b| a.objective.total_cmp(&b.objective))
        .unwrap();
    assert!(best.at_best);
    assert_eq!(best.objective, before.best_objective);
    assert_eq!(before.best_parameters, best.parameters);
    assert_eq!(before.best_parameters.len(), 2);
    for value in before.best_parameters.values() {
        assert!((0.0..=0.9).contains(value), "{value}");
    }

    let c = Coordinator::start(dir.path(), &cluster.urls());
    let after = c.state(&id);
    assert_eq!(after.phase(), pb::CampaignPhase::Cancelled);
    assert_eq!(after.best_parameters, before.best_parameters);
    assert_eq!(after.history, before.history);
    assert_eq!(after.runs, before.runs);
}
