//! The Modelica Association's Reference FMUs, simulated through both interfaces and both FMI
//! versions, against their reference results and against closed forms.

use crate::reference_fmus::{read_reference, reference_fmus};
use calib_model::fmu::{self, Interface};
use calib_model::Run;
use calib_model::SolverOptions;

fn options() -> SolverOptions {
    SolverOptions {
        rtol: 1e-10,
        atol: 1e-12,
        max_steps: 1_000_000,
        ..SolverOptions::default()
    }
}

/// The largest difference per column (name, value), the grid, and the simulated series.
type Compared = (Vec<(String, f64)>, Vec<f64>, Vec<Vec<f64>>);

/// Simulate `model` of FMI `version` on its reference result's grid; the largest absolute
/// difference per column, and the simulated series.
fn against_reference(version: u32, model: &str, interface: Interface) -> Option<Compared> {
    let dir = reference_fmus()?.join(format!("fmi{version}"));
    let m = fmu::open(&dir.join(format!("{model}.fmu")), Some(interface)).unwrap();
    let (header, rows) = read_reference(&dir.join(format!("{model}_ref.csv")));
    let grid: Vec<f64> = rows.iter().map(|r| r[0]).collect();
    let info = m.info();
    let outputs: Vec<usize> = header[1..]
        .iter()
        .map(|n| {
            info.output_index(n)
                .unwrap_or_else(|| panic!("{model} has no output {n}"))
        })
        .collect();
    let params = info.default_vector();
    let t = m
        .simulate(&Run::new(&params, &grid, &outputs, &options()))
        .unwrap();
    let worst = header[1..]
        .iter()
        .enumerate()
        .map(|(k, name)| {
            let e = rows
                .iter()
                .zip(&t.values[k])
                .map(|(r, v)| (r[k + 1] - v).abs())
                .fold(0.0, f64::max);
            (name.clone(), e)
        })
        .collect();
    Some((worst, grid, t.values))
}

const MODELS: [&str; 4] = ["VanDerPol", "BouncingBall", "Dahlquist", "Stair"];

#[test]
fn co_simulation_reproduces_the_reference_results_in_fmi_2_and_3() {
    for version in [2, 3] {
        for model in MODELS {
            // The reference results come from the FMUs' own fixed-step solver, which
            // `doStep` on the same grid runs again: they agree to rounding.
            let Some((worst, grid, _)) = against_reference(version, model, Interface::CoSimulation)
            else {
                return;
            };
            assert!(grid.len() > 10, "{model}");
            for (column, e) in worst {
                assert!(e <= 1e-12, "FMI {version} {model} {column}: {e:e}");
            }
        }
    }
}

#[test]
fn model_exchange_stair_counts_the_seconds_at_its_time_events() {
    for version in [2, 3] {
        let Some((worst, grid, values)) =
            against_reference(version, "Stair", Interface::ModelExchange)
        else {
            return;
        };
        // A time event at each whole second; an output at that second reports the count after it.
        assert_eq!(worst[0].1, 0.0, "FMI {version}");
        let at = |t: f64| values[0][grid.iter().position(|g| (g - t).abs() < 1e-9).unwrap()];
        assert_eq!((at(0.8), at(1.0), at(5.0), at(9.0)), (1.0, 2.0, 6.0, 10.0));
    }
}

#[test]
fn model_exchange_dahlquist_follows_the_exponential() {
    for version in [2, 3] {
        let Some((worst, grid, values)) =
            against_reference(version, "Dahlquist", Interface::ModelExchange)
        else {
            return;
        };
        let exact = grid
            .iter()
            .zip(&values[0])
            .map(|(t, x)| (x - (-t).exp()).abs())
            .fold(0.0, f64::max);
        assert!(exact < 1e-9, "FMI {version}: {exact:e} from exp(-t)");
        // The reference result is explicit Euler with a step of 0.1: 0.9^(t/0.1), at most
        // 0.0192 from exp(-t).
        assert!(
            worst[0].1 < 0.0193,
            "FMI {version}: {:e} from the reference",
            worst[0].1
        );
    }
}

/// Height and velocity of the reference BouncingBall (h0 = 1 m, g = −9.81 m/s², e = 0.7,
/// at rest once it bounces off slower than 0.1 m/s), in closed form.
fn bouncing_ball(t: f64) -> (f64, f64) {
    let (g, e, v_min): (f64, f64, f64) = (9.81, 0.7, 0.1);
    let mut t0 = (2.0 / g).sqrt();
    if t < t0 {
        return (1.0 - 0.5 * g * t * t, -g * t);
    }
    let mut v = e * g * t0;
    loop {
        if v < v_min {
            return (0.0, 0.0);
        }
        let flight = 2.0 * v / g;
        if t < t0 + flight {
            let s = t - t0;
            return (v * s - 0.5 * g * s * s, v - g * s);
        }
        t0 += flight;
        v *= e;
    }
}

#[test]
fn model_exchange_bouncing_ball_bounces_at_the_closed_form_times() {
    for version in [2, 3] {
        let Some((_, grid, values)) =
            against_reference(version, "BouncingBall", Interface::ModelExchange)
        else {
            return;
        };
        let mut worst: f64 = 0.0;
        for (i, t) in grid.iter().enumerate() {
            let (h, v) = bouncing_ball(*t);
            worst = worst
                .max((values[0][i] - h).abs())
                .max((values[1][i] - v).abs());
        }
        assert!(
            worst < 1e-6,
            "FMI {version}: {worst:e} from the closed form"
        );
    }
}

/// The van der Pol oscillator as the FMU writes it, integrated natively.
struct VanDerPol {
    mu: f64,
}

impl calib_model::ode::HybridSystem for VanDerPol {
    fn dim(&self) -> usize {
        2
    }
    fn rhs(&self, _t: f64, y: &[f64], dy: &mut [f64]) {
        dy[0] = y[1];
        dy[1] = self.mu * ((1.0 - y[0] * y[0]) * y[1]) - y[0];
    }
}

#[test]
fn model_exchange_van_der_pol_matches_the_equations_solved_natively() {
    let Some(dir) = reference_fmus() else { return };
    for version in [2, 3] {
        let path = dir.join(format!("fmi{version}/VanDerPol.fmu"));
        let m = fmu::open(&path, Some(Interface::ModelExchange)).unwrap();
        let info = m.info();
        let mu = info.parameter_index("mu").unwrap();
        let outputs = [
            info.output_index("x0").unwrap(),
            info.output_index("x1").unwrap(),
        ];
        let grid: Vec<f64> = (0..=2000).map(|i| i as f64 * 0.01).collect();
        let mut params = info.default_vector();
        params[mu] = 1.7;
        let first = m
            .simulate(&Run::new(&params, &grid, &outputs, &options()))
            .unwrap();
        let mut native = vec![vec![0.0; grid.len()]; 2];
        calib_model::ode::integrate(
            &mut VanDerPol { mu: 1.7 },
            &[2.0, 0.0],
            &grid,
            &options(),
            |i, y| {
                native[0][i] = y[0];
                native[1][i] = y[1];
            },
        )
        .unwrap();
        assert_eq!(
            first.values, native,
            "FMI {version}: the same equations, the same solver"
        );
        // A reused (reset) instance gives what a fresh one gave.
        params[mu] = 0.5;
        let other = m
            .simulate(&Run::new(&params, &grid, &outputs, &options()))
            .unwrap();
        assert_ne!(other.values, first.values);
        params[mu] = 1.7;
        let again = m
            .simulate(&Run::new(&params, &grid, &outputs, &options()))
            .unwrap();
        assert_eq!(again.values, first.values, "FMI {version}");
    }
}

#[test]
fn the_description_gives_parameters_with_start_values_units_and_bounds() {
    let Some(dir) = reference_fmus() else { return };
    for version in [2, 3] {
        let m = fmu::open(&dir.join(format!("fmi{version}/BouncingBall.fmu")), None).unwrap();
        let info = m.info();
        assert!(info.name.starts_with("BouncingBall.me@"), "{}", info.name);
        let e = &info.parameters[info.parameter_index("e").unwrap()];
        assert_eq!((e.default, e.min, e.max), (0.7, 0.5, 1.0), "FMI {version}");
        let g = &info.parameters[info.parameter_index("g").unwrap()];
        assert_eq!(
            (g.default, g.unit.as_str()),
            (-9.81, "m/s2"),
            "FMI {version}"
        );
        assert_eq!(info.outputs[0].name, "h");
        assert_eq!(info.outputs[0].unit, "m");
        assert!(info.effect("offset(h)").is_some());
        assert!(
            info.parameter_index("v_min").is_none(),
            "a constant is not a parameter"
        );
        let cs = fmu::open(
            &dir.join(format!("fmi{version}/BouncingBall.fmu")),
            Some(Interface::CoSimulation),
        )
        .unwrap();
        assert!(cs.info().name.starts_with("BouncingBall.cs@"));
        assert_eq!(
            calib_model::models::find(&info.name).unwrap().info().name,
            info.name
        );
    }
}
