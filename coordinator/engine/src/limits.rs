//! Bounds on what one campaign, analysis or request may ask of a coordinator: every number a
//! campaign (a campaign file, a `SubmitCampaign` message, the web app's JSON) gives that
//! sizes memory or a loop is held to one of these, where the campaign is checked and before
//! anything is allocated. The worker's twin ([`calib_model::limits`]) bounds one
//! simulation; a campaign is held to both.
//!
//! Each bound is generous for real calibrations (tens of parameters, tens of starts) and
//! keeps the worst request a coordinator accepts to memory it can hold: the figures in each
//! constant's documentation are that worst case.

/// Largest dataset (a measurement file) an upload may bring (256 MiB).
pub const MAX_DATASET_BYTES: usize = 256 << 20;

/// Most starts per method (`search.starts`). Each start beyond the nominal one is placed by
/// [`POINTS_PER_START`](crate::optim::screening::POINTS_PER_START) (40) screening points,
/// so 1,000 starts screen 39,960 points by default, within [`MAX_SCREENING`]; with three
/// methods that is 3,000 runs of up to [`MAX_EVALUATIONS`] evaluations each.
pub const MAX_STARTS: usize = 1_000;

/// Most points of the screening batch (`search.screening`). The batch is one Sobol sequence
/// whose generator takes indices below 2^16, and it is held in memory whole: 65,535 points
/// of [`MAX_FREE_PARAMETERS`] coordinates are about 36 MB with their objectives.
pub const MAX_SCREENING: usize = (1 << 16) - 1;

/// Largest evaluation budget of one run (`search.max_evaluations`). A run keeps only its
/// best point, so the budget bounds time (and the store's size), not memory: a million
/// evaluations is days of simulation for any model worth calibrating.
pub const MAX_EVALUATIONS: usize = 1_000_000;

/// Most free parameters and effects together (`parameters` and `effects`). Nelder–Mead
/// holds `n + 1` points of `n` coordinates, differential evolution a population of
/// `max(15, 10 n)` (640 at this bound), a Sobol sensitivity design `samples · (n + 2)`
/// points; the Sobol sequences behind the screening and the designs take at most 256
/// dimensions (`2 n` for Saltelli's design).
pub const MAX_FREE_PARAMETERS: usize = 64;

/// Most model outputs compared with measured columns (`outputs`). The objective keeps each
/// mapped column over the window, at most [`calib_model::limits::MAX_TIMES`] samples: 32
/// outputs of 500,000 samples are 128 MB.
pub const MAX_OUTPUTS: usize = 32;

/// Most fitted intervals of one record (`windows`): every sample of the record is tested
/// against each interval when the objective is built, and the API takes them from clients.
pub const MAX_WINDOWS: usize = 1_000;

/// Longest campaign name, in bytes of UTF-8 (`name`). The name is the folder of the
/// campaign's results; 128 bytes leave room below the 255 most file systems allow.
pub const MAX_NAME_BYTES: usize = 128;

/// Most candidates a diagnosis refits (`diagnosis.refit`): each alone and in pairs, so `k`
/// candidates are `k + k (k − 1) / 2` calibrations (55 at this bound).
pub const MAX_REFIT: usize = 10;

/// Most effects a diagnosis may be restricted to (`diagnosis.candidates`).
pub const MAX_CANDIDATES: usize = 256;

/// Most samples of a sensitivity analysis (`samples`): Sobol's design takes
/// `samples · (parameters + 2)` evaluations, Morris' `samples · (parameters + 1)`; at
/// [`MAX_FREE_PARAMETERS`] that is 270,336 points, about 145 MB.
pub const MAX_SENSITIVITY_SAMPLES: usize = 4096;

/// Most steps of a profile on each side of the best point (`max_steps`); each step is one
/// re-optimisation of the other parameters.
pub const MAX_PROFILE_STEPS: usize = 1_000;

/// Longest idempotency key of `SubmitCampaign` [bytes]: the coordinator keeps every key it
/// was given for as long as it runs.
pub const MAX_IDEMPOTENCY_KEY_BYTES: usize = 256;

/// Largest chunk of an upload [bytes].
pub const MAX_CHUNK_BYTES: usize = 1 << 20;

/// Largest FMU archive `UploadFmu` (and the web app's upload) accepts [bytes]: the most a
/// worker's `UploadFmu` message carries ([`calib_model::limits::MAX_MESSAGE_BYTES`], less
/// room for the message's other fields), since every campaign on it sends it to workers.
/// Its entries and what they inflate to are held to the workers' own limits
/// ([`calib_model::fmu::archive::Limits`]).
pub const MAX_FMU_BYTES: usize = calib_model::limits::MAX_MESSAGE_BYTES - 16;

/// Largest page of `ListCampaigns`.
pub const MAX_PAGE: usize = 100;

// What one measurement file may make the readers allocate: a MAT file is refused naming
// the bound before anything of that size is allocated.

/// Most bytes the compressed (miCOMPRESSED) elements of one MAT v5 file may inflate to,
/// in total: as much as an uncompressed upload may hold
/// ([`MAX_DATASET_BYTES`]), so that compression never lets a file stand
/// for more data than it could hold plainly. Checked while inflating, against what the
/// stream really yields and against what each element declares before it is read.
pub const MAX_MAT_INFLATED_BYTES: usize = 256 << 20;

/// Most values (rows × columns, or the product of all dimensions) of one numeric MAT
/// variable, v4 or v5: 2^24 = 16,777,216 samples, 128 MiB as `f64`, 33 times what a
/// simulation's output grid may hold (`calib_model::limits::MAX_TIMES`).
pub const MAX_MAT_VALUES: usize = 1 << 24;

// Sobol's sequences (screening, starts, sensitivity designs) take indices below 2^16 and at
// most 256 dimensions (twice the parameters for Saltelli's design).
const _: () = {
    assert!(MAX_SCREENING < 1 << 16);
    assert!(2 * MAX_FREE_PARAMETERS <= sobol_burley::NUM_DIMENSIONS as usize);
};

/// A campaign's count of `what` checked against its bound: `Err` says the value and the
/// bound (the caller names the field).
pub fn at_most(value: usize, limit: usize, what: &str) -> Result<(), String> {
    if value > limit {
        Err(format!(
            "{value} is more than the {limit} {what} a campaign may have"
        ))
    } else {
        Ok(())
    }
}

/// Whether `name` may name a campaign: it becomes the folder of the campaign's results
/// (`<out>/<name>/`), so it must be one plain folder name, the same rule for every front
/// door. `Err` says why not.
///
/// Refused: an empty name, one longer than [`MAX_NAME_BYTES`], path separators (`/`, `\`),
/// a drive or stream colon (`:`), control characters, and a leading `.` (which also
/// refuses `.` and `..`, and hidden folders such as the store's `.calib-db`).
pub fn campaign_name(name: &str) -> Result<(), String> {
    if name.is_empty() {
        return Err("is empty".into());
    }
    if name.len() > MAX_NAME_BYTES {
        return Err(format!(
            "is {} bytes long, more than the {MAX_NAME_BYTES} a campaign name may have",
            name.len()
        ));
    }
    if let Some(c) = name
        .chars()
        .find(|c| matches!(c, '/' | '\\' | ':') || c.is_control())
    {
        return Err(format!(
            "{:?} may not hold {c:?}: a campaign name is one folder name (no path \
             separators, colons or control characters)",
            name
        ));
    }
    if name.starts_with('.') {
        return Err(format!(
            "{name:?} may not start with `.`: a campaign name is one plain folder name"
        ));
    }
    if name.trim() != name {
        return Err(format!("{name:?} may not start or end with white space"));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::optim::screening;

    #[test]
    fn the_default_screening_of_the_most_starts_stays_within_its_limit() {
        assert!(screening::default_count(MAX_STARTS, MAX_FREE_PARAMETERS) <= MAX_SCREENING);
    }

    #[test]
    fn campaign_names_are_one_plain_folder_name() {
        for good in [
            "clean",
            "Furuta rig 2",
            "a..b",
            "χ² fit",
            &"n".repeat(MAX_NAME_BYTES),
        ] {
            assert_eq!(campaign_name(good), Ok(()), "{good}");
        }
        for bad in [
            "",
            ".",
            "..",
            "../../x",
            "/etc/x",
            "a/b",
            "a\\b",
            "C:x",
            ".calib-db",
            "tab\there",
            "nul\0",
            " padded",
            &"n".repeat(MAX_NAME_BYTES + 1),
        ] {
            assert!(campaign_name(bad).is_err(), "{bad:?} accepted");
        }
    }
}
