//! What an FMU's native code prints and logs reaches calib's log, and never its channel to
//! the FMU's process: the FMU of `tests/chatty_fmu/` (built with the C compiler at test time)
//! prints to stdout and stderr while it instantiates, steps and gives derivatives, and logs
//! through FMI 2.0's printf-style logger. It simulates to its closed form all the same; its
//! lines and its formatted messages are in `calib simulate`'s log; a crash is explained by
//! its last lines; megabytes of output neither block it nor fill calib's memory or log.

use crate::common::*;
use calib_model::Run;
use std::path::{Path, PathBuf};
use std::process::Output;
use std::sync::OnceLock;

/// The chatty FMU, built once per test program.
fn chatty_fmu() -> Option<&'static Path> {
    static BUILT: OnceLock<Option<(PathBuf, tempfile::TempDir)>> = OnceLock::new();
    BUILT
        .get_or_init(|| {
            let dir = tempfile::tempdir().unwrap();
            let path = c_test_fmu(
                "chatty_fmu",
                "chatty",
                "Chatty",
                &["-lm".into()],
                dir.path(),
            )?;
            Some((path, dir))
        })
        .as_ref()
        .map(|(path, _)| path.as_path())
}

const INTERFACES: [&str; 2] = ["co-simulation", "model-exchange"];

/// `calib --log info simulate` of the chatty FMU through `interface` with `set`, to 4 s
/// every 0.5 s, output x.
fn simulate(fmu: &Path, interface: &str, set: &[&str]) -> Output {
    let mut args = vec![
        "--log",
        "info",
        "simulate",
        fmu.to_str().unwrap(),
        "--interface",
        interface,
        "--stop",
        "4",
        "--step",
        "0.5",
        "--outputs",
        "x",
    ];
    for s in set {
        args.extend(["--set", s]);
    }
    calib(&args)
}

/// The largest difference between the simulated x and x0 exp(-k t), relative to x0.
fn worst_error(out: &Output, k: f64, x0: f64) -> f64 {
    let stdout = String::from_utf8_lossy(&out.stdout);
    let mut lines = stdout.lines();
    assert_eq!(lines.next(), Some("time,x"), "{stdout}");
    let rows: Vec<(f64, f64)> = lines
        .map(|l| {
            let (t, x) = l.split_once(',').unwrap();
            (t.parse().unwrap(), x.parse().unwrap())
        })
        .collect();
    assert_eq!(rows.len(), 9, "{stdout}");
    rows.iter()
        .map(|&(t, x)| (x - x0 * (-k * t).exp()).abs() / x0)
        .fold(0.0, f64::max)
}

/// The line of `log` that holds `text`, if any.
fn line_with<'a>(log: &'a str, text: &str) -> Option<&'a str> {
    log.lines().find(|l| l.contains(text))
}

#[test]
fn a_chatty_fmu_simulates_to_its_closed_form_and_its_output_is_logged() {
    let Some(fmu) = chatty_fmu() else { return };
    for interface in INTERFACES {
        let out = simulate(fmu, interface, &["k=0.7", "x0=2"]);
        let log = String::from_utf8_lossy(&out.stderr);
        assert!(out.status.success(), "{interface}: {log}");
        // Co-Simulation steps with the exact exponential; Model Exchange is integrated
        // within its tolerance.
        let worst = worst_error(&out, 0.7, 2.0);
        let tolerance = if interface == "co-simulation" {
            1e-12
        } else {
            1e-5
        };
        assert!(worst < tolerance, "{interface}: {worst:e}");

        let step = if interface == "co-simulation" {
            "doStep"
        } else {
            "getDerivatives"
        };
        // What the native code printed, each line prefixed with the model identifier:
        // stdout at info, stderr at warn.
        for (text, level) in [
            ("Chatty: chatty instantiated as calib", "INFO"),
            ("Chatty: chatty writes to fd 1", "INFO"),
            ("Chatty: chatty instantiated, said on stderr", "WARN"),
            (&format!("Chatty: chatty says from {step} at t=0"), "INFO"),
            (
                &format!("Chatty: chatty warns on stderr from {step}"),
                "WARN",
            ),
        ] {
            let line = line_with(&log, text).unwrap_or_else(|| panic!("{text}: {log}"));
            assert!(line.contains(level), "{line}");
        }
        // FMI 2.0 log messages with their arguments in place, the value-reference escape
        // as it is, at the level of their status.
        for (text, level) in [
            (
                "[ok] logAll: instantiated calib: -7 42 3000000000 -1234567890123 \
                 9876543210123 77 ff Q 0.5 2.250000 1.000000e-03 100% #r1#",
                "INFO",
            ),
            (
                "[warning] logStatusWarning: a warning about nothing",
                "WARN",
            ),
            (&format!("[ok] logAll: {step} at t = 0, k = 0.7"), "INFO"),
        ] {
            let line = line_with(&log, text).unwrap_or_else(|| panic!("{text}: {log}"));
            assert!(line.contains(level), "{line}");
        }
        assert!(!log.contains("%s"), "{log}");
    }
}

#[test]
fn a_chatty_fmu_that_crashes_is_explained_by_its_last_lines() {
    let Some(fmu) = chatty_fmu() else { return };
    for interface in INTERFACES {
        let step = if interface == "co-simulation" {
            "doStep"
        } else {
            "getDerivatives"
        };
        let out = simulate(fmu, interface, &["mode=1"]);
        let log = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{interface}: {log}");
        let error = line_with(&log, "SIGSEGV").unwrap_or_else(|| panic!("{log}"));
        assert!(
            error.contains("chatty: last words before the crash"),
            "{error}"
        );
        assert!(
            error.contains(&format!("chatty: crashing on purpose in {step}")),
            "{error}"
        );
    }
}

#[test]
fn an_fmu_that_logs_an_error_is_reported_with_its_formatted_message_in_process_too() {
    use calib_model::fmu::{self, Interface};
    use calib_model::Model;
    let Some(fmu) = chatty_fmu() else { return };
    // In this process (no host): the message kept with the instance is formatted too.
    for interface in [Interface::CoSimulation, Interface::ModelExchange] {
        let model = fmu::open_unregistered(fmu, Some(interface), false).unwrap();
        let info = model.info();
        let mut params = info.default_vector();
        let mode = info.parameters.iter().position(|p| p.name == "mode");
        params[mode.unwrap()] = 3.0;
        let x = info.outputs.iter().position(|o| o.name == "x").unwrap();
        let error = model
            .simulate(&Run::new(
                &params,
                &[0.0, 1.0],
                &[x],
                &model.default_options(),
            ))
            .unwrap_err()
            .to_string();
        assert!(
            error.contains("refused at t = 0: k = 0.500 is 50% too chatty"),
            "{interface:?}: {error}"
        );
    }
    // Through `calib simulate` (a host process): the same message.
    let out = simulate(fmu, "co-simulation", &["mode=3"]);
    let log = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{log}");
    assert!(
        log.contains("doStep refused at t = 0: k = 0.500 is 50% too chatty"),
        "{log}"
    );
}

#[test]
fn an_fmu_printing_megabytes_is_neither_blocked_nor_kept_whole() {
    let Some(fmu) = chatty_fmu() else { return };
    for interface in INTERFACES {
        // A line of 3 MB, then 100 000 lines: 11 MB on the FMU's stdout.
        let out = simulate(fmu, interface, &["mode=2", "k=0.3"]);
        let log = String::from_utf8_lossy(&out.stderr);
        assert!(
            out.status.success(),
            "{interface}: {}",
            &log[..log.len().min(4000)]
        );
        let tolerance = if interface == "co-simulation" {
            1e-12
        } else {
            1e-5
        };
        let worst = worst_error(&out, 0.3, 1.0);
        assert!(worst < tolerance, "{interface}: {worst:e}");
        // The long line is cut, the flood is logged up to the limit and then counted.
        let long = line_with(&log, "zzzz").expect("the long line");
        assert!(long.len() < 5000, "{} bytes", long.len());
        assert!(
            long.contains("more bytes not shown"),
            "{}",
            &long[long.len() - 200..]
        );
        assert!(log.contains("chatty flood line 0000000"));
        assert!(!log.contains("chatty flood line 0099999"));
        assert!(log.contains("lines of output in one simulation"));
        assert!(log.len() < 1 << 20, "{} bytes of log", log.len());
    }
}
