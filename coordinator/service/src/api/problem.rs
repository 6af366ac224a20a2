//! [`Problem`], what is wrong with a campaign message and at which field, and the loader's
//! refusals reworded as problems in the words of the form a client fills in.

use calib_proto::v1 as pb;
use tonic::Status;

/// What is wrong with a campaign, and where: a field of the Campaign message, written as a
/// path from it ("outputs[1].measured", "window_stop"; "" for the whole campaign).
#[derive(Debug, Clone, PartialEq)]
pub struct Problem {
    pub field: String,
    pub message: String,
    /// How SubmitCampaign refuses it: INVALID_ARGUMENT, or NOT_FOUND for an unknown dataset.
    pub code: tonic::Code,
}

impl Problem {
    pub(super) fn new(field: impl Into<String>, message: impl Into<String>) -> Self {
        Self {
            field: field.into(),
            message: message.into(),
            code: tonic::Code::InvalidArgument,
        }
    }

    /// SubmitCampaign's refusal: the field named from the request, as every refusal does.
    pub(super) fn status(&self) -> Status {
        let field = if self.field.is_empty() {
            "campaign".to_string()
        } else {
            format!("campaign.{}", self.field)
        };
        Status::new(self.code, format!("{field}: {}", self.message))
    }

    pub(super) fn message(&self) -> pb::CampaignProblem {
        pb::CampaignProblem {
            field: self.field.clone(),
            message: self.message.clone(),
        }
    }

    /// The problem a refusal of the campaign's loader states: its message is "campaign.<field>:
    /// <what>" (a parameter named in the field, "parameters[0] (armFriction)", is its index
    /// alone), "data: <what>" for the dataset's file, else about the whole campaign.
    pub(super) fn of_refusal(status: &Status) -> Self {
        let text = status.message();
        let (field, message) = if let Some(rest) = text.strip_prefix("campaign.") {
            match rest.split_once(": ") {
                Some((field, message)) => (field.to_string(), message.to_string()),
                None => (String::new(), rest.to_string()),
            }
        } else if let Some(rest) = text.strip_prefix("data: ") {
            ("dataset_id".to_string(), rest.to_string())
        } else {
            (String::new(), text.to_string())
        };
        let field = match field.as_str() {
            // The window as a whole: its stop, where the form's window ends.
            "window_start, campaign.window_stop" => "window_stop".to_string(),
            other => without_names(other),
        };
        Self {
            field,
            message: plain_words(&message),
            code: status.code(),
        }
    }
}

/// `field` without the names the loader adds after an index ("parameters[0] (armFriction)"
/// is "parameters[0]").
fn without_names(field: &str) -> String {
    let mut out = String::with_capacity(field.len());
    let mut rest = field;
    while let Some(at) = rest.find(" (") {
        out.push_str(&rest[..at]);
        rest = match rest[at..].find(')') {
            Some(end) => &rest[at + end + 1..],
            None => "",
        };
    }
    out.push_str(rest);
    out
}

/// A loader's message in the words of someone filling in a form rather than a campaign file.
fn plain_words(message: &str) -> String {
    [
        (
            "[[parameters]] or [[effects]] entry",
            "parameter to calibrate",
        ),
        ("[[parameters]] entry", "parameter to calibrate"),
        ("[[outputs]] entry", "output to compare"),
        ("[model.parameters]", "the model's fixed values"),
        ("[window]", "a window"),
    ]
    .iter()
    .fold(without_stored_names(message), |m, (toml, words)| {
        m.replace(toml, words)
    })
}

/// `message` with each uploaded file named as the coordinator stores it ("dataset
/// <64 hex digits>.csv") called "the measurement": the user never saw that name.
fn without_stored_names(message: &str) -> String {
    let mut out = String::with_capacity(message.len());
    let mut rest = message;
    while let Some(at) = rest.find("dataset ") {
        let after = &rest[at + "dataset ".len()..];
        let hex = after.bytes().take_while(u8::is_ascii_hexdigit).count();
        let extension = [".csv", ".txt", ".mat"]
            .iter()
            .find(|e| hex == 64 && after[hex..].starts_with(**e));
        match extension {
            Some(e) => {
                out.push_str(&rest[..at]);
                out.push_str("the measurement");
                rest = &after[hex + e.len()..];
            }
            None => {
                out.push_str(&rest[..at + "dataset ".len()]);
                rest = after;
            }
        }
    }
    out.push_str(rest);
    out
}
