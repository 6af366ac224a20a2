//! FMUs through the Calibration API: uploaded in chunks, kept by their hash across a
//! restart, described; campaigns on them submitted, watched, cancelled, profiled and
//! diagnosed on workers as any other; `calib submit` on an FMU campaign sends the FMU once
//! and gives the runs of `calib calibrate`. On the Reference FMUs, built at test time.

use crate::common::*;
use crate::reference_fmus::reference_fmus;
use calib_proto::v1 as pb;
use calib_proto::v1::calibration_client::CalibrationClient;
use std::io::BufRead;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use tonic::transport::Channel;

fn fmu(version: u32, model: &str) -> Option<PathBuf> {
    Some(reference_fmus()?.join(format!("fmi{version}/{model}.fmu")))
}

/// A `calib` server process (`worker` or `coordinator`) on a port of its choosing; killed
/// when dropped.
struct Process {
    child: Child,
    url: String,
}

impl Process {
    fn start(args: &[&str], says: &str) -> Self {
        let mut child = Command::new(env!("CARGO_BIN_EXE_calib"))
            .args(args)
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .expect("start calib");
        let mut line = String::new();
        std::io::BufReader::new(child.stdout.take().unwrap())
            .read_line(&mut line)
            .unwrap();
        let address = line
            .strip_prefix(says)
            .and_then(|rest| rest.split_whitespace().next())
            .unwrap_or_else(|| panic!("unexpected first line: {line}"));
        Self {
            child,
            url: format!("http://{address}"),
        }
    }

    /// A worker that takes FMUs, its cache in `dir`.
    fn worker(dir: &Path) -> Self {
        let cache = dir.join("worker-fmu-cache");
        Self::start(
            &[
                "worker",
                "--listen",
                "127.0.0.1:0",
                "--slots",
                "2",
                "--allow-fmu",
                "--fmu-cache",
                cache.to_str().unwrap(),
            ],
            "worker listening on ",
        )
    }

    /// A coordinator on a store and an API folder in `dir`, dispatching to `worker`.
    fn coordinator(dir: &Path, worker: &str) -> Self {
        Self::start(
            &[
                "coordinator",
                "--listen",
                "127.0.0.1:0",
                "--workers",
                worker,
                "--db",
                dir.join("db").to_str().unwrap(),
                "--api-dir",
                dir.join("api").to_str().unwrap(),
            ],
            "coordinator listening on ",
        )
    }
}

impl Drop for Process {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

fn submit(campaign: &Path, url: &str, out: &Path) -> (serde_json::Value, String) {
    let run = calib(&[
        "submit",
        campaign.to_str().unwrap(),
        "--coordinator",
        url,
        "--out",
        out.to_str().unwrap(),
        "--json",
    ]);
    let stderr = String::from_utf8_lossy(&run.stderr).into_owned();
    assert!(run.status.success(), "calib submit failed: {stderr}");
    (json_of(&run), stderr)
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

#[test]
fn calib_submit_on_an_fmu_sends_it_once_and_gives_the_runs_of_calib_calibrate() {
    let Some(path) = fmu(2, "VanDerPol") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let campaign = van_der_pol_example(&path, dir.path());
    let worker = Process::worker(dir.path());
    let coordinator = Process::coordinator(dir.path(), &worker.url);
    let (submitted, said) = submit(&campaign, &coordinator.url, &dir.path().join("submitted"));
    assert!(said.contains("uploaded"), "{said}");
    let local = calibrate_json(
        &campaign,
        &dir.path().join("local-db"),
        &dir.path().join("local"),
        &[],
    );
    assert_eq!(submitted["runs"], local["runs"], "the same runs");
    assert_eq!(submitted["best"], local["best"], "the same best point");
    assert_eq!(submitted["model"], local["model"]);
    let mu = submitted["best"]["parameters"]["mu"].as_f64().unwrap();
    assert!((mu / 1.7 - 1.0).abs() < 0.005, "mu = {mu}");
    let kept = dir.path().join("api/fmus");
    let bytes = std::fs::read(&path).unwrap();
    let id = hex(&calib_model::fmu::content_hash(&bytes));
    assert!(kept.join(format!("{id}.fmu")).is_file(), "kept by its hash");

    // A coordinator started again on the same folders still has it: submitted again, the
    // FMU is not sent and the campaign is the one it finished.
    drop(coordinator);
    let coordinator = Process::coordinator(dir.path(), &worker.url);
    let (again, said) = submit(&campaign, &coordinator.url, &dir.path().join("again"));
    assert!(
        said.contains("on the coordinator already") && !said.contains("uploaded"),
        "{said}"
    );
    assert!(said.contains("already known"), "{said}");
    assert_eq!(again["runs"], local["runs"]);
}

/// A client of the coordinator at `url`, and a runtime to drive it.
fn client(url: &str) -> (tokio::runtime::Runtime, CalibrationClient<Channel>) {
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(1)
        .enable_all()
        .build()
        .unwrap();
    let client = runtime
        .block_on(CalibrationClient::connect(url.to_string()))
        .unwrap()
        .max_encoding_message_size(64 << 20);
    (runtime, client)
}

fn chunks(name: &str, bytes: &[u8], size: usize) -> Vec<pb::FmuChunk> {
    bytes
        .chunks(size)
        .enumerate()
        .map(|(i, data)| pb::FmuChunk {
            file_name: if i == 0 { name.into() } else { String::new() },
            data: data.to_vec(),
        })
        .collect()
}

#[test]
fn an_fmu_uploaded_in_chunks_is_named_by_its_hash_and_described() {
    let Some(path) = fmu(2, "BouncingBall") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let worker = Process::worker(dir.path());
    let coordinator = Process::coordinator(dir.path(), &worker.url);
    let (runtime, mut client) = client(&coordinator.url);
    let bytes = std::fs::read(&path).unwrap();
    let fmu = runtime
        .block_on(client.upload_fmu(tokio_stream::iter(chunks("BouncingBall.fmu", &bytes, 4096))))
        .unwrap()
        .into_inner();
    let id = hex(&calib_model::fmu::content_hash(&bytes));
    assert_eq!(fmu.id, id, "the hash workers key their FMU cache by");
    assert_eq!(
        (fmu.file_name.as_str(), fmu.size),
        ("BouncingBall.fmu", bytes.len() as u64)
    );
    let names: Vec<&str> = fmu.models.iter().map(|m| m.name.as_str()).collect();
    assert_eq!(
        names,
        [
            format!("BouncingBall.me@{}", &id[..12]),
            format!("BouncingBall.cs@{}", &id[..12])
        ]
    );
    let e = fmu.models[0]
        .parameters
        .iter()
        .find(|p| p.name == "e")
        .expect("parameter e");
    assert_eq!((e.default_value, e.min, e.max), (0.7, 0.5, 1.0));
    let outputs: Vec<&str> = fmu.models[0]
        .outputs
        .iter()
        .map(|o| o.name.as_str())
        .collect();
    assert_eq!(outputs, ["h", "v", "der(h)", "der(v)"]);
    assert_eq!(fmu.models[0].outputs[0].unit, "m");

    // The same bytes again, in other chunks: the same FMU.
    let again = runtime
        .block_on(client.upload_fmu(tokio_stream::iter(chunks("ball.fmu", &bytes, 1 << 20))))
        .unwrap()
        .into_inner();
    assert_eq!(again, fmu);
    let got = runtime
        .block_on(client.get_fmu(pb::GetFmuRequest { id: id.clone() }))
        .unwrap()
        .into_inner();
    assert_eq!(got, fmu);
    let missing = runtime
        .block_on(client.get_fmu(pb::GetFmuRequest { id: "0".repeat(64) }))
        .unwrap_err();
    assert_eq!(missing.code(), tonic::Code::NotFound, "{missing:?}");

    // Refusals name the field; the coordinator keeps serving.
    let refused = |chunks: Vec<pb::FmuChunk>| {
        let status = runtime
            .block_on(client.clone().upload_fmu(tokio_stream::iter(chunks)))
            .unwrap_err();
        assert_eq!(status.code(), tonic::Code::InvalidArgument, "{status:?}");
        status.message().to_string()
    };
    let message = refused(chunks("ball.zip", &bytes, 4096));
    assert!(message.starts_with("file_name:"), "{message}");
    let message = refused(chunks("ball.fmu", b"not a zip archive", 4096));
    assert!(message.starts_with("fmu: "), "{message}");
    let message = refused(chunks("ball.fmu", &vec![0; (1 << 20) + 1], 2 << 20));
    assert!(message.starts_with("data: a chunk"), "{message}");
    let message = refused(chunks("big.fmu", &vec![0; 64 << 20], 1 << 20));
    assert!(
        message.starts_with("fmu: the archive is more than"),
        "{message}"
    );

    // A campaign naming an FMU the coordinator lacks, or a model the FMU does not have.
    let campaign = |fmu_id: &str, model: &str| pb::SubmitCampaignRequest {
        // Complete but for the FMU and model named: those are what is refused.
        campaign: Some(pb::Campaign {
            model: model.into(),
            fmu_id: fmu_id.into(),
            dataset_id: "0".repeat(64),
            outputs: vec![pb::Output {
                model: "x0".into(),
                measured: "h".into(),
                ..Default::default()
            }],
            parameters: vec![pb::Parameter {
                name: "mu".into(),
                min: 0.1,
                max: 5.0,
                ..Default::default()
            }],
            window_stop: 2.0,
            ..Default::default()
        }),
        idempotency_key: String::new(),
    };
    let csv = (0..=20)
        .map(|i| format!("{},{}\n", i as f64 * 0.1, 1.0))
        .collect::<String>();
    let dataset = runtime
        .block_on(
            client.upload_dataset(tokio_stream::iter(vec![pb::DatasetChunk {
                file_name: "drop.csv".into(),
                time_column: "time".into(),
                data: format!("time,h\n{csv}").into_bytes(),
            }])),
        )
        .unwrap()
        .into_inner();
    let submit = |mut request: pb::SubmitCampaignRequest| {
        request.campaign.as_mut().unwrap().dataset_id = dataset.id.clone();
        runtime
            .block_on(client.clone().submit_campaign(request))
            .unwrap_err()
    };
    let status = submit(campaign(&"1".repeat(64), ""));
    assert_eq!(status.code(), tonic::Code::NotFound, "{status:?}");
    assert!(
        status.message().starts_with("campaign.fmu_id:"),
        "{status:?}"
    );
    let status = submit(campaign(&id, "VanDerPol.me@000000000000"));
    assert_eq!(status.code(), tonic::Code::InvalidArgument, "{status:?}");
    assert!(
        status.message().starts_with("campaign.model:"),
        "{status:?}"
    );
    let status = submit(campaign("", names[1]));
    assert!(
        status.message().starts_with("campaign.fmu_id:"),
        "{status:?}"
    );
}

/// Every state of a campaign's watch, to its end.
fn watch(
    runtime: &tokio::runtime::Runtime,
    client: &mut CalibrationClient<Channel>,
    id: &str,
) -> Vec<pb::CampaignState> {
    runtime.block_on(async {
        let mut stream = client
            .watch_campaign(pb::WatchCampaignRequest { id: id.into() })
            .await
            .unwrap()
            .into_inner();
        let mut states = Vec::new();
        while let Some(s) = stream.message().await.unwrap() {
            states.push(s);
        }
        states
    })
}

#[test]
fn a_campaign_on_an_uploaded_fmu_is_watched_cancelled_profiled_and_diagnosed() {
    let Some(path) = fmu(2, "VanDerPol") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let campaign = van_der_pol_example(&path, dir.path());
    let worker = Process::worker(dir.path());
    let coordinator = Process::coordinator(dir.path(), &worker.url);
    let (runtime, mut client) = client(&coordinator.url);
    let fmu = runtime
        .block_on(client.upload_fmu(tokio_stream::iter(chunks(
            "VanDerPol.fmu",
            &std::fs::read(&path).unwrap(),
            1 << 20,
        ))))
        .unwrap()
        .into_inner();
    let record = std::fs::read(dir.path().join("data/vanderpol.csv")).unwrap();
    let dataset = runtime
        .block_on(
            client.upload_dataset(tokio_stream::iter(vec![pb::DatasetChunk {
                file_name: "vanderpol.csv".into(),
                time_column: "time".into(),
                data: record,
            }])),
        )
        .unwrap()
        .into_inner();
    let text = std::fs::read_to_string(&campaign).unwrap();
    let mut message = calib_service::api::spec::campaign_message(&text, &dataset.id).unwrap();
    message.fmu_id = fmu.id.clone();

    // Cancelled at once, a long campaign stops.
    let mut long = message.clone();
    long.name = "vanderpol-long".into();
    long.search = Some(pb::Search {
        methods: vec!["differential-evolution".into()],
        starts: Some(4),
        max_evaluations: Some(100_000),
        seed: 3,
        screening: None,
        cma_population: None,
    });
    let started = runtime
        .block_on(client.submit_campaign(pb::SubmitCampaignRequest {
            campaign: Some(long),
            idempotency_key: String::new(),
        }))
        .unwrap()
        .into_inner();
    runtime
        .block_on(client.cancel_campaign(pb::CancelCampaignRequest {
            id: started.id.clone(),
        }))
        .unwrap();
    let last = watch(&runtime, &mut client, &started.id).pop().unwrap();
    assert_eq!(last.phase(), pb::CampaignPhase::Cancelled, "{last:?}");
    assert!(last.evaluations < 400_000, "{last:?}");

    // The campaign of the file, on the uploaded FMU: calib calibrate's result.
    let submitted = runtime
        .block_on(client.submit_campaign(pb::SubmitCampaignRequest {
            campaign: Some(message),
            idempotency_key: String::new(),
        }))
        .unwrap()
        .into_inner();
    let last = watch(&runtime, &mut client, &submitted.id).pop().unwrap();
    assert_eq!(last.phase(), pb::CampaignPhase::Finished, "{last:?}");
    let result: serde_json::Value = serde_json::from_str(&last.result_json).unwrap();
    let local = calibrate_json(
        &campaign,
        &dir.path().join("local-db"),
        &dir.path().join("local"),
        &[],
    );
    assert_eq!(result["runs"], local["runs"]);
    let mu = result["best"]["parameters"]["mu"].as_f64().unwrap();
    assert!((mu / 1.7 - 1.0).abs() < 0.005, "mu = {mu}");

    // Profiled: mu is pinned down, its interval around the truth.
    let profile = runtime.block_on(async {
        let mut stream = client
            .profile(pb::ProfileRequest {
                id: submitted.id.clone(),
                parameters: vec![],
                max_steps: 0,
            })
            .await
            .unwrap()
            .into_inner();
        let mut last = None;
        while let Some(s) = stream.message().await.unwrap() {
            last = Some(s);
        }
        last.unwrap()
    });
    assert_eq!(profile.phase(), pb::CampaignPhase::Finished, "{profile:?}");
    let report: serde_json::Value = serde_json::from_str(&profile.report_json).unwrap();
    assert_typed_twin(profile.profile.as_ref(), &profile.report_json, &[]);
    assert!(profile.sensitivity.is_none());
    let mu_profile = &report["parameters"][0];
    assert_eq!(mu_profile["identifiable"], true, "{report}");
    let (low, high) = (
        mu_profile["ci_low"].as_f64().unwrap(),
        mu_profile["ci_high"].as_f64().unwrap(),
    );
    assert!(low < 1.7 && 1.7 < high && high - low < 0.1, "{low} {high}");

    // Diagnosed: the record lacks nothing the model could add.
    let diagnosis = runtime.block_on(async {
        let mut stream = client
            .diagnose(pb::DiagnoseRequest {
                id: submitted.id.clone(),
                discover: false,
            })
            .await
            .unwrap()
            .into_inner();
        let mut last = None;
        while let Some(s) = stream.message().await.unwrap() {
            last = Some(s);
        }
        last.unwrap()
    });
    assert_eq!(
        diagnosis.phase(),
        pb::CampaignPhase::Finished,
        "{diagnosis:?}"
    );
    let report: serde_json::Value = serde_json::from_str(&diagnosis.report_json).unwrap();
    assert_eq!(report["selected"], serde_json::json!([]), "{report}");
    assert_typed_twin(diagnosis.report.as_ref(), &diagnosis.report_json, &[]);
}
