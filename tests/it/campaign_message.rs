//! Properties of the Calibration API's campaign message on its way in: whatever JSON the web
//! app's `SubmitCampaign` route receives (arbitrary bytes, a good request with one value
//! replaced anywhere in it), decoding it, writing its campaign file and loading that file
//! never panic; what loads is within the coordinator's limits.

use calib_engine::campaign::Campaign;
use calib_engine::limits;
use calib_proto::v1 as pb;
use calib_service::api::spec;
use proptest::prelude::*;
use proptest::sample::select;
use serde_json::Value;
use std::path::Path;

const CASES: u32 = 128;

const GOOD: &str = r#"name = "props"
[model]
name = "furuta"
stop_time = 40.0
[model.parameters]
theta0 = 0.5
[measurement]
file = "data/run.csv"
time_column = "time_s"
[[outputs]]
model = "armJoint.phi"
measured = "arm"
[[outputs]]
model = "pendulumJoint.phi"
measured = "pendulum"
sigma = 0.002
[[parameters]]
name = "armFriction"
nominal = 0.012
min = 0.0
max = 0.9
[[effects]]
name = "viscous_friction.arm"
min = 0.0
max = 0.1
[window]
start = 0.0
stop = 35.0
[search]
methods = ["nelder-mead", "powell"]
starts = 2
max_evaluations = 100
seed = 3
screening = 50
[solver]
rtol = 1e-8
max_steps = 100000
[diagnosis]
holdout_start = 35.0
holdout_stop = 40.0
refit = 2
candidates = ["viscous_friction.pendulum"]
"#;

/// The good request, as the web app receives it.
fn good() -> Value {
    let campaign = spec::campaign_message(GOOD, &"ab".repeat(32)).unwrap();
    serde_json::to_value(pb::SubmitCampaignRequest {
        campaign: Some(campaign),
        idempotency_key: "k".into(),
    })
    .unwrap()
}

fn replacements() -> Vec<Value> {
    let text = |s: &str| Value::String(s.into());
    vec![
        Value::Null,
        Value::Bool(true),
        0.into(),
        (-1).into(),
        1000.into(),
        1001.into(),
        65536.into(),
        1_000_000_000u64.into(),
        1_000_000_000_000u64.into(),
        u64::MAX.into(),
        i64::MIN.into(),
        1e308.into(),
        (-1e-308).into(),
        0.5.into(),
        text(""),
        text("../../x"),
        text("/etc/passwd"),
        text(".calib-db"),
        text("a\u{0}b"),
        text(&"n".repeat(10_000)),
        text("NaN"),
        text("furuta"),
        text("armFriction"),
        text("armJoint.phi"),
        text("powell"),
        Value::Array(vec![]),
        Value::Array(vec![Value::Null; 3]),
        Value::Array(vec![text("armFriction"); 100]),
        serde_json::json!({ "name": "armFriction", "min": 0, "max": 1 }),
        serde_json::json!({}),
    ]
}

/// Replace the value that `path` leads to in `value` (each step picks among the entries of
/// an object or the elements of an array, modulo their number) by `with`.
fn replace_at(value: &mut Value, path: &[usize], with: Value) {
    let Some((&step, rest)) = path.split_first() else {
        *value = with;
        return;
    };
    let next = match value {
        Value::Object(map) if !map.is_empty() => {
            let n = map.len();
            map.values_mut().nth(step % n)
        }
        Value::Array(list) if !list.is_empty() => {
            let n = list.len();
            list.get_mut(step % n)
        }
        _ => None,
    };
    match next {
        Some(inner) if !rest.is_empty() => replace_at(inner, rest, with),
        Some(inner) => *inner = with,
        None => *value = with,
    }
}

/// Decode, write the campaign file, load it: never a panic; a loaded campaign within the
/// limits.
fn submit(body: &[u8]) {
    let Ok(request) = serde_json::from_slice::<pb::SubmitCampaignRequest>(body) else {
        return;
    };
    let Some(campaign) = request.campaign else {
        return;
    };
    let folder = Path::new("/srv/calib-api/datasets");
    let Ok(spec) = spec::campaign_spec(&campaign, &folder.join("x.csv"), "time_s") else {
        return;
    };
    if let Ok(c) = Campaign::from_spec(spec, &folder.join("submitted-campaign.toml")) {
        // The campaign file it is stored as resolves to the same campaign.
        let stored = Campaign::parse(&c.spec, &folder.join("submitted-campaign.toml"))
            .unwrap_or_else(|e| panic!("{e}\n{}", c.spec));
        assert_eq!(
            stored.identity(&[0; 32]),
            c.identity(&[0; 32]),
            "{}",
            c.spec
        );
        assert!((1..=limits::MAX_STARTS).contains(&c.search.starts));
        assert!(c.search.max_evaluations <= limits::MAX_EVALUATIONS);
        assert!(c.search.screening.unwrap_or(0) <= limits::MAX_SCREENING);
        assert!(c.free.len() <= limits::MAX_FREE_PARAMETERS);
        assert!(c.outputs.len() <= limits::MAX_OUTPUTS);
        assert!(c.diagnosis.refit <= limits::MAX_REFIT);
        assert_eq!(limits::campaign_name(&c.name), Ok(()));
    }
}

#[test]
fn the_good_request_loads() {
    let body = serde_json::to_vec(&good()).unwrap();
    let request: pb::SubmitCampaignRequest = serde_json::from_slice(&body).unwrap();
    let spec = spec::campaign_spec(
        &request.campaign.unwrap(),
        Path::new("/srv/x.csv"),
        "time_s",
    )
    .unwrap();
    Campaign::from_spec(spec, Path::new("/srv/submitted-campaign.toml")).unwrap();
}

/// Any count up to a few times its limit, or anything a `uint64` holds.
fn count(limit: usize) -> impl Strategy<Value = u64> {
    prop_oneof![0..=4 * limit as u64, any::<u64>()]
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(CASES))]

    #[test]
    fn search_numbers_beyond_their_limits_are_refused_naming_the_field(
        starts in count(limits::MAX_STARTS),
        screening in count(limits::MAX_SCREENING),
        max_evaluations in count(limits::MAX_EVALUATIONS),
    ) {
        let mut campaign = spec::campaign_message(GOOD, "x").unwrap();
        let search = campaign.search.as_mut().unwrap();
        search.starts = Some(starts);
        search.screening = Some(screening);
        search.max_evaluations = Some(max_evaluations);
        let Ok(spec) = spec::campaign_spec(&campaign, Path::new("/srv/x.csv"), "time_s") else {
            // Only what a campaign file cannot hold (above i64::MAX) is refused here.
            prop_assert!([starts, screening, max_evaluations].iter().any(|n| *n > i64::MAX as u64));
            return Ok(());
        };
        let loaded = Campaign::from_spec(spec, Path::new("/srv/submitted-campaign.toml"));
        let beyond = [
            ("search.starts", starts == 0 || starts > limits::MAX_STARTS as u64),
            ("search.max_evaluations", max_evaluations > limits::MAX_EVALUATIONS as u64),
            ("search.screening", screening > limits::MAX_SCREENING as u64),
        ];
        match beyond.iter().find(|(_, out)| *out) {
            Some((field, _)) => {
                let e = loaded.expect_err("refused");
                prop_assert_eq!(&e.field, field, "{}", e);
            }
            // Within the limits, only a budget too small for the parameters is refused.
            None => prop_assert!(loaded.is_ok() || max_evaluations < 8, "{:?}", loaded.err()),
        }
    }

    #[test]
    fn arbitrary_bytes_never_panic(bytes in prop::collection::vec(any::<u8>(), 0..400)) {
        submit(&bytes);
    }

    #[test]
    fn a_good_request_with_values_replaced_never_panics(
        edits in prop::collection::vec(
            (prop::collection::vec(0..64usize, 1..5), select(replacements())),
            1..4,
        )
    ) {
        let mut request = good();
        for (path, with) in edits {
            replace_at(&mut request, &path, with);
        }
        submit(&serde_json::to_vec(&request).unwrap());
    }
}
