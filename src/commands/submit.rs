//! `calib submit`, `calib status`, `calib watch`, `calib cancel`: campaigns on a
//! coordinator, through its Calibration API.

use super::{Failure, Outcome};
use calib_engine::campaign::Campaign;
use calib_proto::v1 as pb;
use calib_proto::v1::calibration_client::CalibrationClient;
use std::path::{Path, PathBuf};

/// Bytes per upload chunk.
const CHUNK: usize = 1 << 20;

#[derive(clap::Args)]
pub struct CoordinatorArg {
    /// The coordinator's address, e.g. http://calib-coordinator:50050 (https:// when it
    /// serves TLS).
    #[arg(long, value_name = "URL", env = "CALIB_COORDINATOR")]
    coordinator: String,
    #[command(flatten)]
    dial: super::security::DialArgs,
}

type Client = CalibrationClient<calib_security::client::SecureChannel>;

#[derive(clap::Args)]
pub struct SubmitArgs {
    /// Campaign file (TOML), as for `calib calibrate`; its measurement file is uploaded.
    campaign: PathBuf,
    #[command(flatten)]
    coordinator: CoordinatorArg,
    /// Results folder: result.json and the plots go to DIR/<campaign name>/ [default:
    /// results/ beside the campaign file].
    #[arg(long, value_name = "DIR")]
    out: Option<PathBuf>,
    /// Print result.json on standard output instead of a summary.
    #[arg(long)]
    json: bool,
    /// Submit and print the campaign's id, without waiting for it to finish.
    #[arg(long)]
    detach: bool,
}

#[derive(clap::Args)]
pub struct StatusArgs {
    /// A campaign's id; without it, every campaign of the coordinator.
    id: Option<String>,
    #[command(flatten)]
    coordinator: CoordinatorArg,
}

#[derive(clap::Args)]
pub struct IdArgs {
    /// The campaign's id (from `calib submit` or `calib status`).
    id: String,
    #[command(flatten)]
    coordinator: CoordinatorArg,
}

async fn connect(arg: &CoordinatorArg) -> Result<Client, Failure> {
    let url = &arg.coordinator;
    let security = arg.dial.client()?;
    let endpoint = security
        .endpoint(url, None)
        .map_err(|e| Failure::input(format!("--coordinator {e}")))?;
    let channel = endpoint.connect().await.map_err(|e| {
        let why = calib_security::failure::tls_failure(&e).unwrap_or_else(|| source(&e));
        Failure::internal(format!("cannot reach the coordinator at {url}: {why}"))
    })?;
    Ok(CalibrationClient::new(security.authorize(channel))
        .max_decoding_message_size(64 << 20)
        .max_encoding_message_size(64 << 20))
}

/// The innermost cause of a transport error, which says what went wrong.
fn source(e: &(dyn std::error::Error + 'static)) -> String {
    let mut inner = e;
    while let Some(next) = inner.source() {
        inner = next;
    }
    inner.to_string()
}

fn rpc(status: tonic::Status) -> Failure {
    if let Some(refused) = calib_security::failure::refusal(&status) {
        return Failure::internal(format!("coordinator: {refused}"));
    }
    let message = format!("coordinator: {}", status.message());
    match status.code() {
        tonic::Code::InvalidArgument | tonic::Code::NotFound => Failure::input(message),
        _ => Failure::internal(message),
    }
}

pub fn submit(args: SubmitArgs) -> Outcome {
    let campaign = Campaign::load(&args.campaign).map_err(|e| Failure::input(e.to_string()))?;
    // A campaign on an FMU: its archive, as read when the campaign was loaded.
    let fmu = match calib_model::fmu::hash_of(&campaign.model.info().name) {
        None => None,
        Some(_) => Some(
            calib_model::fmu::archive_of(&campaign.model.info().name).ok_or_else(|| {
                Failure::input(format!(
                    "{}: `model.fmu`: the FMU cannot be read again",
                    args.campaign.display()
                ))
            })?,
        ),
    };
    let text = std::fs::read_to_string(&args.campaign)
        .map_err(|e| Failure::input(format!("{}: {e}", args.campaign.display())))?;
    let runtime = super::runtime()?;
    runtime.block_on(async {
        let mut client = connect(&args.coordinator).await?;
        // Each record uploaded once, however many experiments read it.
        let mut uploaded: Vec<((PathBuf, String), String)> = Vec::new();
        let mut ids = Vec::new();
        for experiment in campaign.experiments() {
            let key = (experiment.measurement_file, experiment.time_column);
            let id = match uploaded.iter().find(|(k, _)| *k == key) {
                Some((_, id)) => id.clone(),
                None => {
                    let id = upload(&mut client, &key.0, &key.1).await?;
                    uploaded.push((key, id.clone()));
                    id
                }
            };
            ids.push(id);
        }
        let several = !campaign.experiment.is_empty();
        let mut message = if several {
            calib_service::api::spec::campaign_message_on(&text, "", &ids)
        } else {
            calib_service::api::spec::campaign_message(&text, &ids[0])
        }
        .map_err(|e| Failure::input(format!("{}: {e}", args.campaign.display())))?;
        if let Some((hash, archive)) = &fmu {
            message.fmu_id = send_fmu(&mut client, hash, archive, &campaign).await?;
        }
        let submitted = client
            .submit_campaign(pb::SubmitCampaignRequest {
                campaign: Some(message),
                idempotency_key: String::new(),
            })
            .await
            .map_err(rpc)?
            .into_inner();
        if args.detach {
            println!("{}", submitted.id);
            return Ok(());
        }
        eprintln!(
            "campaign {} {} ({})",
            campaign.name,
            if submitted.started {
                "submitted"
            } else {
                "already known"
            },
            submitted.id
        );
        let last = follow(&args.coordinator, client, &submitted.id).await?;
        finish(&args, &campaign, &last)
    })
}

/// Upload the record `file` (its time in `time_column`) as a dataset; its id.
async fn upload(client: &mut Client, file: &Path, time_column: &str) -> Result<String, Failure> {
    let bytes =
        std::fs::read(file).map_err(|e| Failure::input(format!("{}: {e}", file.display())))?;
    let file_name = file
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let chunks: Vec<pb::DatasetChunk> = bytes
        .chunks(CHUNK)
        .enumerate()
        .map(|(i, data)| pb::DatasetChunk {
            file_name: if i == 0 {
                file_name.clone()
            } else {
                String::new()
            },
            time_column: if i == 0 {
                time_column.to_string()
            } else {
                String::new()
            },
            data: data.to_vec(),
        })
        .collect();
    let dataset = client
        .upload_dataset(tokio_stream::iter(chunks))
        .await
        .map_err(rpc)?
        .into_inner();
    eprintln!(
        "{}: dataset {} ({} samples)",
        file.display(),
        dataset.id,
        dataset.samples
    );
    Ok(dataset.id)
}

/// Make sure the coordinator has the FMU `archive` (content hash `hash`): asked first, sent
/// only when it lacks it. Its id.
async fn send_fmu(
    client: &mut Client,
    hash: &[u8; 32],
    archive: &[u8],
    campaign: &Campaign,
) -> Result<String, Failure> {
    let id: String = hash.iter().map(|b| format!("{b:02x}")).collect();
    match client.get_fmu(pb::GetFmuRequest { id: id.clone() }).await {
        Ok(_) => {
            eprintln!("FMU {id} is on the coordinator already");
            return Ok(id);
        }
        Err(status) if status.code() == tonic::Code::NotFound => {}
        Err(status) => return Err(rpc(status)),
    }
    // Named after the model's identifier ("VanDerPol.me@…" was VanDerPol.fmu).
    let model = &campaign.model.info().name;
    let identifier = model
        .rsplit_once('@')
        .map_or(model.as_str(), |(head, _)| head);
    let identifier = identifier
        .strip_suffix(".me")
        .or_else(|| identifier.strip_suffix(".cs"))
        .unwrap_or(identifier);
    let file_name = format!("{identifier}.fmu");
    let chunks: Vec<pb::FmuChunk> = archive
        .chunks(CHUNK)
        .enumerate()
        .map(|(i, data)| pb::FmuChunk {
            file_name: if i == 0 {
                file_name.clone()
            } else {
                String::new()
            },
            data: data.to_vec(),
        })
        .collect();
    let uploaded = client
        .upload_fmu(tokio_stream::iter(chunks))
        .await
        .map_err(rpc)?
        .into_inner();
    if uploaded.id != id {
        return Err(Failure::internal(format!(
            "coordinator: the FMU was kept as `{}`, not as its hash `{id}`",
            uploaded.id
        )));
    }
    eprintln!("FMU {id} uploaded ({} bytes)", archive.len());
    Ok(id)
}

/// How long a follower keeps reconnecting to a coordinator it lost (restarted, rescheduled,
/// cut off) before it gives up.
const RECONNECT_FOR: std::time::Duration = std::time::Duration::from_secs(300);

/// Print the campaign's progress until it ends; its last state. A lost connection (the
/// coordinator restarted or the network cut) is dialed again for up to `RECONNECT_FOR`:
/// every message is the whole state, so nothing is missed.
async fn follow(
    arg: &CoordinatorArg,
    mut client: Client,
    id: &str,
) -> Result<pb::CampaignState, Failure> {
    use std::time::{Duration, Instant};
    let mut last: Option<pb::CampaignState> = None;
    let mut shown = Instant::now() - Duration::from_secs(1);
    let mut lost_since: Option<Instant> = None;
    loop {
        let lost = match client
            .watch_campaign(pb::WatchCampaignRequest { id: id.into() })
            .await
        {
            Ok(stream) => {
                let mut stream = stream.into_inner();
                loop {
                    match stream.message().await {
                        Ok(Some(state)) => {
                            lost_since = None;
                            if shown.elapsed() >= Duration::from_millis(200) {
                                eprintln!("{}", line(&state));
                                shown = Instant::now();
                            }
                            last = Some(state);
                        }
                        // The stream ends with the campaign; one that ends while the
                        // campaign runs was cut by a coordinator going down.
                        Ok(None) if last.as_ref().is_some_and(|s| s.phase != running()) => {
                            let last = last.expect("checked");
                            eprintln!("{}", line(&last));
                            return Ok(last);
                        }
                        Ok(None) => break "the coordinator ended the watch".to_string(),
                        Err(status) if transient(&status) => break status.message().to_string(),
                        Err(status) => return Err(rpc(status)),
                    }
                }
            }
            Err(status) if transient(&status) => status.message().to_string(),
            Err(status) => return Err(rpc(status)),
        };
        let since = *lost_since.get_or_insert_with(Instant::now);
        eprintln!("coordinator lost ({lost}); reconnecting");
        loop {
            if since.elapsed() > RECONNECT_FOR {
                return Err(Failure::internal(format!(
                    "coordinator {}: unreachable for {} s ({lost}); the campaign goes on \
                     there: `calib watch {id}` follows it again",
                    arg.coordinator,
                    RECONNECT_FOR.as_secs()
                )));
            }
            tokio::time::sleep(Duration::from_secs(1)).await;
            if let Ok(fresh) = connect(arg).await {
                client = fresh;
                break;
            }
        }
    }
}

fn running() -> i32 {
    pb::CampaignPhase::Running as i32
}

/// A failure of the connection rather than an answer of the coordinator.
fn transient(status: &tonic::Status) -> bool {
    matches!(
        status.code(),
        tonic::Code::Unavailable | tonic::Code::Unknown | tonic::Code::Cancelled
    ) && calib_security::failure::refusal(status).is_none()
}

fn phase_word(phase: i32) -> &'static str {
    match pb::CampaignPhase::try_from(phase).unwrap_or(pb::CampaignPhase::Unspecified) {
        pb::CampaignPhase::Running => "running",
        pb::CampaignPhase::Finished => "finished",
        pb::CampaignPhase::Failed => "failed",
        pb::CampaignPhase::Cancelled => "cancelled",
        pb::CampaignPhase::Unspecified => "unknown",
    }
}

fn line(s: &pb::CampaignState) -> String {
    let mut text = format!(
        "{}  {:<10} {:<20} {} evaluations",
        s.id,
        phase_word(s.phase),
        s.name,
        s.evaluations
    );
    if s.best_objective.is_finite() {
        text.push_str(&format!(", best {:.6e}", s.best_objective));
    }
    if !s.failure.is_empty() {
        text.push_str(&format!("  [{}]", s.failure));
    }
    text
}

/// Write what a finished campaign left, as `calib calibrate` does.
fn finish(args: &SubmitArgs, campaign: &Campaign, state: &pb::CampaignState) -> Outcome {
    match pb::CampaignPhase::try_from(state.phase) {
        Ok(pb::CampaignPhase::Finished) => {}
        _ => {
            return Err(Failure::internal(format!(
                "campaign {} {}{}",
                state.id,
                phase_word(state.phase),
                if state.failure.is_empty() {
                    String::new()
                } else {
                    format!(": {}", state.failure)
                }
            )))
        }
    }
    let folder =
        super::calibrate::results_root(&args.campaign, args.out.as_deref()).join(&campaign.name);
    std::fs::create_dir_all(&folder)
        .map_err(|e| Failure::internal(format!("{}: {e}", folder.display())))?;
    let outcome = match &state.result {
        Some(result) => calib_service::api::result::outcome_of(result),
        None => {
            return Err(Failure::internal(format!(
                "coordinator: campaign {} finished without a result (a coordinator older than \
                 this client?)",
                state.id
            )))
        }
    };
    // The coordinator's own text when it sends it, else the same document from its values.
    let text = if state.result_json.is_empty() {
        outcome.to_json_text()
    } else {
        state.result_json.clone()
    };
    let mut written = Vec::new();
    let result = folder.join("result.json");
    std::fs::write(&result, format!("{text}\n"))
        .map_err(|e| Failure::internal(format!("{}: {e}", result.display())))?;
    written.push(result);
    for (name, svg) in &state.plots {
        // Names come from the coordinator: keep them inside the folder.
        let Some(name) = Path::new(name).file_name() else {
            continue;
        };
        let path = folder.join(name);
        std::fs::write(&path, svg)
            .map_err(|e| Failure::internal(format!("{}: {e}", path.display())))?;
        written.push(path);
    }
    if args.json {
        println!("{text}");
    } else {
        print!("{}", calib_analysis::report::table::summary_of(&outcome));
        for path in written {
            println!("wrote {}", path.display());
        }
    }
    Ok(())
}

pub fn status(args: StatusArgs) -> Outcome {
    let runtime = super::runtime()?;
    runtime.block_on(async {
        let mut client = connect(&args.coordinator).await?;
        match args.id {
            Some(id) => {
                let state = client
                    .get_campaign(pb::GetCampaignRequest { id })
                    .await
                    .map_err(rpc)?
                    .into_inner();
                println!("{}", line(&state));
            }
            None => {
                let mut token = String::new();
                loop {
                    let page = client
                        .list_campaigns(pb::ListCampaignsRequest {
                            page_size: 0,
                            page_token: token,
                        })
                        .await
                        .map_err(rpc)?
                        .into_inner();
                    for state in &page.campaigns {
                        println!("{}", line(state));
                    }
                    if page.next_page_token.is_empty() {
                        break;
                    }
                    token = page.next_page_token;
                }
            }
        }
        Ok(())
    })
}

pub fn watch(args: IdArgs) -> Outcome {
    let runtime = super::runtime()?;
    runtime.block_on(async {
        let client = connect(&args.coordinator).await?;
        follow(&args.coordinator, client, &args.id)
            .await
            .map(|_| ())
    })
}

pub fn cancel(args: IdArgs) -> Outcome {
    let runtime = super::runtime()?;
    runtime.block_on(async {
        let mut client = connect(&args.coordinator).await?;
        let state = client
            .cancel_campaign(pb::CancelCampaignRequest { id: args.id })
            .await
            .map_err(rpc)?
            .into_inner();
        println!("{}", line(&state));
        Ok(())
    })
}
