//! The domain's errors as a client reads them: the fields of the message it sent, not of
//! the campaign file made from it.

use calib_engine::error::Error;
use tonic::Status;

/// The campaign message's name of a campaign file's field (`model.stop_time` is the
/// message's `stop_time`), for refusals that name what the client sent.
fn message_field(field: &str) -> String {
    let renamed = match field {
        "" => return "campaign".into(),
        "window" => "window_start, campaign.window_stop",
        "window.start" => "window_start",
        "window.stop" => "window_stop",
        "model.name" | "model" => "model",
        "model.stop_time" => "stop_time",
        other => {
            if let Some(name) = other.strip_prefix("model.parameters.") {
                return format!("campaign.model_parameters[{name:?}]");
            }
            if other.starts_with("experiments[") {
                // An experiment's `window` is its message's `windows`, its `fixed.x` the
                // map's entry.
                let (head, tail) = other.split_once(").").unwrap_or((other, ""));
                let tail = match tail {
                    "window" | "window.start" | "window.stop" => "windows".to_string(),
                    t => match t.strip_prefix("fixed.") {
                        Some(name) => format!("fixed[{name:?}]"),
                        None => t.to_string(),
                    },
                };
                return if tail.is_empty() {
                    format!("campaign.{other}")
                } else {
                    format!("campaign.{head}).{tail}")
                };
            }
            other.strip_prefix("solver.").unwrap_or(other)
        }
    };
    format!("campaign.{renamed}")
}

/// How an error of the domain reads to a client.
pub(super) fn status(e: Error) -> Status {
    match e {
        Error::Campaign(c) => {
            Status::invalid_argument(format!("{}: {}", message_field(&c.field), c.message))
        }
        Error::Measurement(m) => Status::invalid_argument(format!("data: {m}")),
        Error::InvalidRequest(m) => Status::invalid_argument(m),
        other => Status::internal(other.to_string()),
    }
}

/// The refusal of a request naming a campaign this coordinator does not hold.
pub(super) fn not_found(id: &str) -> Status {
    Status::not_found(format!("id: no campaign `{id}` on this coordinator"))
}
