//! Properties of the campaign loader: whatever a campaign file holds (arbitrary bytes,
//! TOML-like text, a good campaign with one line changed), loading it never panics; it
//! gives a campaign a worker will accept, or a `CampaignError` with a message, located on a
//! line of the file when it names one.

use calib_engine::campaign::{Campaign, CampaignError};
use calib_engine::limits::{
    campaign_name, MAX_EVALUATIONS, MAX_FREE_PARAMETERS, MAX_OUTPUTS, MAX_REFIT, MAX_SCREENING,
    MAX_STARTS,
};
use calib_model::{limits, validate};
use proptest::prelude::*;
use proptest::sample::select;
use std::path::Path;

const CASES: u32 = 96;

const GOOD: &str = r#"name = "props"
[model]
name = "furuta"
stop_time = 40.0
[model.parameters]
theta0 = 0.5
pend_mass = 0.035
[measurement]
file = "data/run.csv"
time_column = "time_s"
[[outputs]]
model = "armJoint.phi"
measured = "arm"
weight = 1.0
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
[solver]
rtol = 1e-8
atol = 1e-10
max_steps = 100000
[diagnosis]
holdout_start = 35.0
holdout_stop = 40.0
refit = 2
candidates = ["viscous_friction.pendulum", "offset(armJoint.phi)"]
"#;

fn path() -> &'static Path {
    Path::new("/campaigns/props.toml")
}

/// What loading must give: a campaign a worker accepts, or an explained error.
fn check(text: &str, result: Result<Campaign, CampaignError>) {
    match result {
        Ok(c) => assert_acceptable(&c),
        Err(e) => {
            assert_eq!(e.file, path());
            assert!(!e.message.trim().is_empty(), "no message: {e:?}");
            if let Some(line) = e.line {
                let lines = text.lines().count().max(1);
                assert!(
                    (1..=lines + 1).contains(&line),
                    "line {line} of {lines}: {e}"
                );
            }
        }
    }
}

/// A resolved campaign stays within what the worker checks, so none of its requests can be
/// refused for its settings.
fn assert_acceptable(c: &Campaign) {
    let info = c.model.info();
    assert_eq!(c.base.len(), info.full_len());
    for (i, v) in c.base.iter().enumerate() {
        assert!(
            validate::parameter_value(info, i, *v).is_ok(),
            "base {i} = {v}"
        );
    }
    for p in &c.free {
        assert!(
            validate::bounds(info, p.index, p.min, p.max).is_ok(),
            "{p:?}"
        );
        assert!(p.min <= p.nominal && p.nominal <= p.max, "{p:?}");
    }
    assert!(!c.free.is_empty() && !c.outputs.is_empty());
    assert!(0.0 <= c.window.0 && c.window.0 < c.window.1 && c.window.1 <= c.stop_time);
    assert!(validate::stop_time(c.stop_time).is_ok());
    assert!(limits::RTOL.contains(&c.solver.rtol));
    assert!(limits::ATOL.contains(&c.solver.atol));
    assert!(limits::MAX_STEPS.contains(&(c.solver.max_steps as u64)));
    // And within the coordinator's own limits: nothing it runs sizes more than they allow.
    assert!(
        (1..=MAX_STARTS).contains(&c.search.starts),
        "{:?}",
        c.search
    );
    assert!(c.search.max_evaluations <= MAX_EVALUATIONS);
    assert!(c.search.screening.unwrap_or(0) <= MAX_SCREENING);
    assert!(c.free.len() <= MAX_FREE_PARAMETERS && c.outputs.len() <= MAX_OUTPUTS);
    assert!(c.diagnosis.refit <= MAX_REFIT);
    assert_eq!(campaign_name(&c.name), Ok(()), "{:?}", c.name);
}

fn keys() -> Vec<&'static str> {
    vec![
        "name",
        "stop_time",
        "theta0",
        "armFriction",
        "file",
        "time_column",
        "model",
        "measured",
        "weight",
        "sigma",
        "scale",
        "nominal",
        "min",
        "max",
        "start",
        "stop",
        "methods",
        "starts",
        "max_evaluations",
        "seed",
        "screening",
        "rtol",
        "atol",
        "max_steps",
        "holdout_start",
        "holdout_stop",
        "refit",
        "candidates",
        "colour",
    ]
}

fn values() -> Vec<&'static str> {
    vec![
        "0",
        "-0.0",
        "1",
        "0.5",
        "-1",
        "1e400",
        "1e-400",
        "nan",
        "inf",
        "-inf",
        "18446744073709551615",
        "9223372036854775807",
        "-9223372036854775808",
        "10000001",
        "1000",
        "1001",
        "65535",
        "65536",
        "1000000000",
        "1000000000000",
        "\"../../x\"",
        "\"/abs/x\"",
        "\".calib-db\"",
        "\"a\\\\b\"",
        "\"furuta\"",
        "\"hx_lowfi\"",
        "\"armFriction\"",
        "\"armJoint.phi\"",
        "\"log10\"",
        "\"variance\"",
        "\"\"",
        "\"\\u0000\"",
        "[]",
        "[\"powell\"]",
        "[\"simplex\"]",
        "[1, \"a\"]",
        "{ a = 1 }",
        "true",
        "1979-05-27T07:32:00Z",
        "'''x'''",
    ]
}

fn headers() -> Vec<&'static str> {
    vec![
        "[model]",
        "[model.parameters]",
        "[measurement]",
        "[[outputs]]",
        "[[parameters]]",
        "[[effects]]",
        "[window]",
        "[search]",
        "[solver]",
        "[diagnosis]",
        "[[model]]",
        "[outputs]",
        "[",
        "[[]]",
    ]
}

/// One line of TOML-like text: a header, a `key = value`, or junk.
fn toml_line() -> impl Strategy<Value = String> {
    prop_oneof![
        2 => select(headers()).prop_map(str::to_string),
        6 => (select(keys()), select(values())).prop_map(|(k, v)| format!("{k} = {v}")),
        1 => "\\PC{0,20}",
        1 => Just(String::new()),
    ]
}

/// A good campaign with one line deleted, duplicated, or given another value or name.
fn mutated_good() -> impl Strategy<Value = String> {
    let lines: Vec<String> = GOOD.lines().map(str::to_string).collect();
    let n = lines.len();
    (
        0..n,
        0..4usize,
        select(values()),
        select(keys()),
        "\\PC{0,6}",
    )
        .prop_map(move |(i, how, value, key, junk)| {
            let mut lines = lines.clone();
            match how {
                0 => {
                    lines.remove(i);
                }
                1 => {
                    let line = lines[i].clone();
                    lines.insert(i, line);
                }
                2 => {
                    if let Some((k, _)) = lines[i].split_once(" = ") {
                        lines[i] = format!("{k} = {value}");
                    } else {
                        lines[i] = format!("{key} = {value}");
                    }
                }
                _ => {
                    // GOOD is ASCII: every byte offset is a character boundary.
                    let middle = lines[i].len() / 2;
                    lines[i].insert_str(middle, &junk);
                }
            }
            lines.join("\n")
        })
}

#[test]
fn the_good_campaign_resolves() {
    let c = Campaign::parse(GOOD, path()).unwrap();
    assert_acceptable(&c);
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(CASES))]

    #[test]
    fn arbitrary_bytes_give_an_explained_error(bytes in prop::collection::vec(any::<u8>(), 0..400)) {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("c.toml");
        std::fs::write(&file, &bytes).unwrap();
        match Campaign::load(&file) {
            Ok(c) => assert_acceptable(&c),
            Err(e) => {
                prop_assert_eq!(&e.file, &file);
                prop_assert!(!e.message.trim().is_empty());
            }
        }
        let text = String::from_utf8_lossy(&bytes);
        check(&text, Campaign::parse(&text, path()));
    }

    #[test]
    fn toml_like_text_gives_a_campaign_or_an_explained_error(
        lines in prop::collection::vec(toml_line(), 0..40)
    ) {
        let text = lines.join("\n");
        check(&text, Campaign::parse(&text, path()));
    }

    #[test]
    fn a_good_campaign_with_one_line_changed_gives_a_campaign_or_an_explained_error(
        text in mutated_good()
    ) {
        check(&text, Campaign::parse(&text, path()));
    }
}
