//! Bit-exact fingerprints of the ODE solvers' results: every output f64's bits, the step,
//! right-hand-side and event counts, and the failure (its kind, time and text) of a set of
//! simulations through both integrators (Dormand–Prince and Runge–Kutta–Chebyshev): the
//! `furuta` model with its stick–slip events, the heat exchangers at their own tolerance
//! (RKC) and at rtol 1e-8 (Dormand–Prince), runs that hit the step limit or leave the property
//! tables, hybrid systems whose events accumulate, and the Reference FMUs through Model
//! Exchange. A change to the solvers that moves one bit of one result fails here.
//!
//! The constants were recorded from the solvers as they stood before the drivers were merged
//! into one; on a mismatch the test prints every case's fingerprint in the form of the table.

use crate::reference_fmus::{read_reference, reference_fmus};
use calib_model::fmu::{self, Interface};
use calib_model::models::{furuta::Furuta, hx};
use calib_model::ode::{self, rkc, HybridSystem};
use calib_model::Run;
use calib_model::{Model, SimulationError, SolverOptions, SolverStats, Trajectory};

/// The fingerprint of one result (its stats and every value's bits, or its error), and what
/// it is in words.
fn fingerprint(result: &Result<(SolverStats, Vec<Vec<f64>>), SimulationError>) -> Case {
    let mut hasher = blake3::Hasher::new();
    match result {
        Ok((stats, values)) => {
            hasher.update(b"ok");
            for count in [
                stats.accepted_steps,
                stats.rejected_steps,
                stats.rhs_evaluations,
                stats.events,
            ] {
                hasher.update(&(count as u64).to_le_bytes());
            }
            for series in values {
                hasher.update(&(series.len() as u64).to_le_bytes());
                for v in series {
                    hasher.update(&v.to_bits().to_le_bytes());
                }
            }
        }
        // `Debug` prints each f64 so that it reads back to the same bits.
        Err(e) => {
            hasher.update(format!("err {e:?}").as_bytes());
        }
    }
    let summary = match result {
        Ok((s, _)) => format!(
            "{} steps, {} rejected, {} rhs, {} events",
            s.accepted_steps, s.rejected_steps, s.rhs_evaluations, s.events
        ),
        Err(e) => e.to_string(),
    };
    Case {
        name: String::new(),
        fingerprint: hasher.finalize().to_hex()[..32].to_string(),
        summary,
    }
}

/// One simulation's fingerprint.
struct Case {
    name: String,
    fingerprint: String,
    summary: String,
}

impl Case {
    fn named(self, name: String) -> Self {
        Self { name, ..self }
    }
}

fn of_trajectory(r: Result<Trajectory, SimulationError>) -> Case {
    fingerprint(&r.map(|t| (t.stats, t.values)))
}

/// Compare each case's fingerprint with the recorded one; on a mismatch print the whole
/// table as it now stands.
fn check(recorded: &[(&str, &str)], actual: &[Case]) {
    let names: Vec<&str> = actual.iter().map(|c| c.name.as_str()).collect();
    let expected: Vec<&str> = recorded.iter().map(|(n, _)| *n).collect();
    let table: String = actual
        .iter()
        .map(|c| {
            format!(
                "    // {}\n    (\"{}\", \"{}\"),\n",
                c.summary, c.name, c.fingerprint
            )
        })
        .collect();
    assert_eq!(names, expected, "cases changed; now:\n{table}");
    let moved: Vec<&str> = recorded
        .iter()
        .zip(actual)
        .filter(|((_, want), got)| *want != got.fingerprint)
        .map(|((n, _), _)| *n)
        .collect();
    assert!(
        moved.is_empty(),
        "results moved in {moved:?}; now:\n{table}"
    );
}

fn seconds(step: f64, end: f64) -> Vec<f64> {
    (0..=(end / step).round() as usize)
        .map(|i| i as f64 * step)
        .collect()
}

/// Parameters set by name.
type Settings = Vec<(&'static str, f64)>;

/// Full parameter vector of `model` with the named entries set.
fn with(model: &dyn Model, set: &[(&str, f64)]) -> Vec<f64> {
    let info = model.info();
    let mut p = info.default_vector();
    for (name, value) in set {
        let i = (0..p.len())
            .find(|&i| info.name_at(i) == *name)
            .unwrap_or_else(|| panic!("no parameter {name}"));
        p[i] = *value;
    }
    p
}

fn simulate(model: &dyn Model, p: &[f64], grid: &[f64], options: &SolverOptions) -> Case {
    let outputs: Vec<usize> = (0..model.info().outputs.len()).collect();
    of_trajectory(model.simulate(&Run::new(p, grid, &outputs, options)))
}

const FURUTA: &[(&str, &str)] = &[
    // 582 steps, 11 rejected, 3590 rhs, 30 events
    ("default", "43a37cd1a1610ae7ed6044227ec7800c"),
    // 114 steps, 4 rejected, 713 rhs, 3 events
    ("frictions", "592f31ab18a2834a41acf088978be046"),
    // 8 steps, 0 rejected, 50 rhs, 0 events
    ("stuck", "edcd31b0f3de9bbf32f5005d0f647239"),
    // 353 steps, 9 rejected, 2187 rhs, 13 events
    ("effects", "f4f895a8821fefa15ed5e99c893b3158"),
    // 591 steps, 33 rejected, 3746 rhs, 0 events
    ("frictionless", "3262c0c2c000abe25ee06289412b113d"),
    // 173 steps, 22 rejected, 1201 rhs, 29 events
    ("loose", "7fc911e52d4990b76656514f0e8e1544"),
    // step limit of 40 steps reached at t = 0.6691554871237764 s
    ("step limit", "18fee3f4b28a99ed30e274dfac2c2e13"),
];

#[test]
fn furuta_results_are_bit_for_bit_the_recorded_ones() {
    let model = Furuta::new();
    let grid = seconds(0.01, 10.0);
    let default = SolverOptions::default();
    let cases: Vec<(&str, Settings, SolverOptions)> = vec![
        ("default", vec![], default),
        (
            "frictions",
            vec![("armFriction", 0.05), ("pendulumFriction", 0.02)],
            default,
        ),
        (
            "stuck",
            vec![("armFriction", 0.5), ("pendulumFriction", 0.3)],
            default,
        ),
        (
            "effects",
            vec![
                ("theta0", 2.5),
                ("dphi0", 3.0),
                ("viscous_friction.arm", 0.002),
                ("quadratic_drag.pendulum", 0.0005),
                ("stiffness.arm", 0.01),
                ("torque_bias.pendulum", 0.001),
            ],
            default,
        ),
        (
            "frictionless",
            vec![("armFriction", 0.0), ("pendulumFriction", 0.0)],
            default,
        ),
        (
            "loose",
            vec![("dtheta0", -4.0)],
            SolverOptions {
                rtol: 1e-5,
                atol: 1e-7,
                ..default
            },
        ),
        (
            "step limit",
            vec![],
            SolverOptions {
                max_steps: 40,
                ..default
            },
        ),
    ];
    let actual: Vec<Case> = cases
        .iter()
        .map(|(name, set, options)| {
            let p = with(&model, set);
            simulate(&model, &p, &grid, options).named(name.to_string())
        })
        .collect();
    check(FURUTA, &actual);
}

const HX: &[(&str, &str)] = &[
    // 1039 steps, 76 rejected, 2864 rhs, 0 events
    ("hx_highfi rkc", "924f93a314e5a5272a805dc164988d59"),
    // 1039 steps, 76 rejected, 2864 rhs, 0 events
    ("hx_highfi rkc half", "8f8dda366f7958033c906e308e417f6c"),
    // 998 steps, 58 rejected, 6338 rhs, 0 events
    ("hx_highfi dopri", "14ce9841700c94141f4471b9ee8c4c2d"),
    // simulation failed at t = 113.21609276828929 s: refrigerant enthalpy 201.35 kJ/kg at 3.0364 bar is subcooled liquid (saturated liquid 201.35 kJ/kg), which the property tables do not cover
    (
        "hx_highfi rkc subcooled",
        "0d7cd2e5d0d9ab0a487039c23c828cab",
    ),
    // simulation failed at t = 113.21609574993464 s: refrigerant enthalpy 201.35 kJ/kg at 3.0364 bar is subcooled liquid (saturated liquid 201.35 kJ/kg), which the property tables do not cover
    (
        "hx_highfi dopri subcooled",
        "a1aac39acf438031b11fcee908dafabf",
    ),
    // step limit of 30 steps reached at t = 6.121455610966399 s
    (
        "hx_highfi rkc step limit",
        "790f9bfc25b6f4b3aa5a31e01987db82",
    ),
    // step limit of 30 steps reached at t = 6.093718331184582 s
    (
        "hx_highfi dopri step limit",
        "bd6c3acacd97c57166c7796ffc3a362a",
    ),
    // 506 steps, 10 rejected, 1546 rhs, 0 events
    ("hx_lowfi rkc", "46e4274fe4a11ba2eb067336cbb000a2"),
    // 506 steps, 10 rejected, 1546 rhs, 0 events
    ("hx_lowfi rkc half", "769a3a83881caaf9e164a65b473195ac"),
    // 689 steps, 18 rejected, 4244 rhs, 0 events
    ("hx_lowfi dopri", "ab2f999b4a82c638c1ca440cd10f9c33"),
    // simulation failed at t = 113.28580618002138 s: refrigerant enthalpy 201.08 kJ/kg at 3.0140 bar is subcooled liquid (saturated liquid 201.08 kJ/kg), which the property tables do not cover
    ("hx_lowfi rkc subcooled", "e7e5ddfaf70cb9717d67d724fb00848f"),
    // simulation failed at t = 113.28581036239402 s: refrigerant enthalpy 201.08 kJ/kg at 3.0140 bar is subcooled liquid (saturated liquid 201.08 kJ/kg), which the property tables do not cover
    (
        "hx_lowfi dopri subcooled",
        "72a164fa435f93a91e423bba88f3ea08",
    ),
    // step limit of 30 steps reached at t = 11.857320791317578 s
    (
        "hx_lowfi rkc step limit",
        "fa2534b5e60d1e2c33c1c1274f7ba97e",
    ),
    // step limit of 30 steps reached at t = 8.192042325435157 s
    (
        "hx_lowfi dopri step limit",
        "a7e8e3aed1fbb23e54ae49c6f8e174d4",
    ),
];

#[test]
fn heat_exchanger_results_are_bit_for_bit_the_recorded_ones() {
    let grid = seconds(1.0, 300.0);
    let half = seconds(0.5, 300.0);
    let tight = SolverOptions::default();
    let mut actual = Vec::new();
    for model in [hx::highfi(), hx::lowfi()] {
        let name = model.info().name.clone();
        let own = model.default_options();
        let p = model.info().default_vector();
        // Leaves the property tables during the inlet-enthalpy ramp.
        let mut subcooled = p.clone();
        subcooled[7] = 180.0;
        let cases = [
            ("rkc", &p, &grid, own),
            ("rkc half", &p, &half, own),
            ("dopri", &p, &grid, tight),
            ("rkc subcooled", &subcooled, &grid, own),
            ("dopri subcooled", &subcooled, &grid, tight),
            (
                "rkc step limit",
                &p,
                &grid,
                SolverOptions {
                    max_steps: 30,
                    ..own
                },
            ),
            (
                "dopri step limit",
                &p,
                &grid,
                SolverOptions {
                    max_steps: 30,
                    ..tight
                },
            ),
        ];
        for (case, p, grid, options) in cases {
            actual.push(simulate(&model, p, grid, &options).named(format!("{name} {case}")));
        }
    }
    check(HX, &actual);
}

/// A ball dropped from 1 m bouncing with restitution 0.5; its bounces accumulate, after which
/// it rests on the floor if it may.
struct Ball {
    may_rest: bool,
    resting: bool,
}

impl HybridSystem for Ball {
    fn dim(&self) -> usize {
        2
    }
    fn rhs(&self, _t: f64, y: &[f64], dy: &mut [f64]) {
        dy[0] = y[1];
        dy[1] = if self.resting { 0.0 } else { -9.81 };
    }
    fn event_count(&self) -> usize {
        1
    }
    fn events(&self, _t: f64, y: &[f64], g: &mut [f64]) {
        g[0] = if y[1] < 0.0 { y[0] } else { 1.0 };
    }
    fn on_event(&mut self, _t: f64, y: &mut [f64], _event: usize) {
        y[0] = 0.0;
        y[1] *= -0.5;
    }
    fn on_chattering(&mut self, _t: f64, y: &mut [f64], _event: usize) -> bool {
        if self.may_rest {
            self.resting = true;
            y.fill(0.0);
        }
        self.may_rest
    }
}

/// Van der Pol's oscillator, stiff for a large `mu`, with an event each time `x` falls
/// through 0 that kicks the speed.
struct VanDerPol {
    mu: f64,
}

impl HybridSystem for VanDerPol {
    fn dim(&self) -> usize {
        2
    }
    fn rhs(&self, _t: f64, y: &[f64], dy: &mut [f64]) {
        dy[0] = y[1];
        dy[1] = self.mu * (1.0 - y[0] * y[0]) * y[1] - y[0];
    }
    fn event_count(&self) -> usize {
        1
    }
    fn events(&self, _t: f64, y: &[f64], g: &mut [f64]) {
        g[0] = y[0];
    }
    fn on_event(&mut self, _t: f64, y: &mut [f64], _event: usize) {
        y[1] *= 1.01;
    }
}

type Integrator<S> = fn(
    &mut S,
    &[f64],
    &[f64],
    &SolverOptions,
    &mut dyn FnMut(usize, &[f64]),
) -> Result<SolverStats, SimulationError>;

fn run<S: HybridSystem>(
    integrate: Integrator<S>,
    system: &mut S,
    y0: &[f64],
    grid: &[f64],
    options: &SolverOptions,
) -> Case {
    let mut values = vec![vec![f64::NAN; grid.len()]; y0.len()];
    let r = integrate(system, y0, grid, options, &mut |i, y| {
        for (series, v) in values.iter_mut().zip(y) {
            series[i] = *v;
        }
    });
    fingerprint(&r.map(|stats| (stats, values)))
}

fn dopri<S: HybridSystem>(
    s: &mut S,
    y0: &[f64],
    grid: &[f64],
    o: &SolverOptions,
    out: &mut dyn FnMut(usize, &[f64]),
) -> Result<SolverStats, SimulationError> {
    ode::integrate(s, y0, grid, o, out)
}

fn chebyshev<S: HybridSystem>(
    s: &mut S,
    y0: &[f64],
    grid: &[f64],
    o: &SolverOptions,
    out: &mut dyn FnMut(usize, &[f64]),
) -> Result<SolverStats, SimulationError> {
    rkc::integrate(s, y0, grid, o, out)
}

const SYSTEMS: &[(&str, &str)] = &[
    // 74 steps, 0 rejected, 507 rhs, 61 events
    ("dopri ball rests true", "2a66a3dd84e3888f1214c1fc238f281f"),
    // events chatter at t = 1.3545709229631266 s: 32 events within 3.0000000000000004e-9 s, the last `event #0`, and the model has no mode that stops the switching
    ("dopri ball rests false", "eade55e9deb15e7508033a4d8a932926"),
    // 75 steps, 0 rejected, 3367 rhs, 61 events
    ("rkc ball rests true", "6d2cc92502d0fdab63210c8b1b1adc04"),
    // events chatter at t = 1.3545709229641583 s: 32 events within 3.0000000000000004e-9 s, the last `event #0`, and the model has no mode that stops the switching
    ("rkc ball rests false", "356c0aab655f3a9e4f2a39821bdbeb88"),
    // 665 steps, 65 rejected, 4387 rhs, 5 events
    (
        "dopri van der Pol mu 1 default",
        "7c92331ba2bf9fee37ef58afb834d1d9",
    ),
    // 179 steps, 42 rejected, 1333 rhs, 5 events
    (
        "dopri van der Pol mu 1 loose",
        "3c638f54b008a3c089428d750db59ba5",
    ),
    // 1393 steps, 6 rejected, 8397 rhs, 1 events
    (
        "dopri van der Pol mu 30 default",
        "8d10b1d6da51383a1d2fb7bd3329b9e4",
    ),
    // 603 steps, 18 rejected, 3729 rhs, 1 events
    (
        "dopri van der Pol mu 30 loose",
        "4925cc78dbbc62e80160b4de61b00348",
    ),
    // 40 steps, 0 rejected, 242 rhs, 0 events
    ("dopri repeated times", "1e539fb6122fa149c86aba9c00c0d205"),
    // 0 steps, 0 rejected, 0 rhs, 0 events
    ("dopri start only", "f37d666ca08310d204cf1424b6533a21"),
    // 21146 steps, 0 rejected, 60358 rhs, 5 events
    (
        "rkc van der Pol mu 1 default",
        "66907048b5761018b869fc2957f42957",
    ),
    // 2126 steps, 2 rejected, 6181 rhs, 5 events
    (
        "rkc van der Pol mu 1 loose",
        "9c30a13be445d7fdc042df41bbbcfdf8",
    ),
    // 10284 steps, 2 rejected, 23050 rhs, 1 events
    (
        "rkc van der Pol mu 30 default",
        "6c63ab49b5018522e912182133504d93",
    ),
    // 889 steps, 3 rejected, 2517 rhs, 1 events
    (
        "rkc van der Pol mu 30 loose",
        "6a6c23bed09b3fb1b62af0fc95739248",
    ),
    // 1162 steps, 0 rejected, 2595 rhs, 0 events
    ("rkc repeated times", "9a6042f9a76cef74de492e0609793526"),
    // 0 steps, 0 rejected, 0 rhs, 0 events
    ("rkc start only", "f37d666ca08310d204cf1424b6533a21"),
];

#[test]
fn hybrid_systems_integrate_bit_for_bit_as_recorded() {
    let default = SolverOptions::default();
    let loose = SolverOptions {
        rtol: 1e-5,
        atol: 1e-7,
        ..default
    };
    let grid = seconds(0.05, 3.0);
    let mut actual = Vec::new();
    for (method, integrate) in [
        ("dopri", dopri::<Ball> as Integrator<Ball>),
        ("rkc", chebyshev::<Ball>),
    ] {
        for may_rest in [true, false] {
            let mut ball = Ball {
                may_rest,
                resting: false,
            };
            let r = run(integrate, &mut ball, &[1.0, 0.0], &grid, &loose);
            actual.push(r.named(format!("{method} ball rests {may_rest}")));
        }
    }
    let vdp_grid = seconds(0.1, 30.0);
    for (method, integrate) in [
        ("dopri", dopri::<VanDerPol> as Integrator<VanDerPol>),
        ("rkc", chebyshev::<VanDerPol>),
    ] {
        for mu in [1.0, 30.0] {
            for (tol, options) in [("default", default), ("loose", loose)] {
                let r = run(
                    integrate,
                    &mut VanDerPol { mu },
                    &[2.0, 0.0],
                    &vdp_grid,
                    &options,
                );
                actual.push(r.named(format!("{method} van der Pol mu {mu} {tol}")));
            }
        }
        // Outputs at the start only, repeated times, and none at all.
        let r = run(
            integrate,
            &mut VanDerPol { mu: 1.0 },
            &[2.0, 0.0],
            &[0.0, 0.0, 0.5, 0.5, 2.0],
            &default,
        );
        actual.push(r.named(format!("{method} repeated times")));
        let r = run(
            integrate,
            &mut VanDerPol { mu: 1.0 },
            &[2.0, 0.0],
            &[0.0],
            &default,
        );
        actual.push(r.named(format!("{method} start only")));
    }
    check(SYSTEMS, &actual);
}

const FMUS: &[(&str, &str)] = &[
    // 440 steps, 49 rejected, 2936 rhs, 0 events
    ("fmi2 VanDerPol default", "0efc2ea76ed03c22bb5d5fb11049cdea"),
    // 1092 steps, 12 rejected, 6626 rhs, 0 events
    ("fmi2 VanDerPol tight", "47c8f1b8f4a8a32a6ef229b93f716226"),
    // 24 steps, 0 rejected, 157 rhs, 11 events
    (
        "fmi2 BouncingBall default",
        "8d2ad30d678ecf2598da119066ea494f",
    ),
    // 25 steps, 0 rejected, 163 rhs, 11 events
    (
        "fmi2 BouncingBall tight",
        "dd24bbf9e372e4321f12839de40cd40a",
    ),
    // 91 steps, 0 rejected, 548 rhs, 0 events
    ("fmi2 Dahlquist default", "b2dc42acebca2faa6f989e2ea3671e3d"),
    // 221 steps, 0 rejected, 1328 rhs, 0 events
    ("fmi2 Dahlquist tight", "4635cad3c280dacb63cb946db02de43a"),
    // 24 steps, 0 rejected, 155 rhs, 9 events
    ("fmi2 Stair default", "55c9c703acdfdcab508d4780feb9bd8c"),
    // 24 steps, 0 rejected, 155 rhs, 9 events
    ("fmi2 Stair tight", "55c9c703acdfdcab508d4780feb9bd8c"),
    // 440 steps, 49 rejected, 2936 rhs, 0 events
    ("fmi3 VanDerPol default", "0efc2ea76ed03c22bb5d5fb11049cdea"),
    // 1092 steps, 12 rejected, 6626 rhs, 0 events
    ("fmi3 VanDerPol tight", "47c8f1b8f4a8a32a6ef229b93f716226"),
    // 24 steps, 0 rejected, 157 rhs, 11 events
    (
        "fmi3 BouncingBall default",
        "8d2ad30d678ecf2598da119066ea494f",
    ),
    // 25 steps, 0 rejected, 163 rhs, 11 events
    (
        "fmi3 BouncingBall tight",
        "dd24bbf9e372e4321f12839de40cd40a",
    ),
    // 91 steps, 0 rejected, 548 rhs, 0 events
    ("fmi3 Dahlquist default", "b2dc42acebca2faa6f989e2ea3671e3d"),
    // 221 steps, 0 rejected, 1328 rhs, 0 events
    ("fmi3 Dahlquist tight", "4635cad3c280dacb63cb946db02de43a"),
    // 24 steps, 0 rejected, 155 rhs, 9 events
    ("fmi3 Stair default", "55c9c703acdfdcab508d4780feb9bd8c"),
    // 24 steps, 0 rejected, 155 rhs, 9 events
    ("fmi3 Stair tight", "55c9c703acdfdcab508d4780feb9bd8c"),
];

#[test]
fn model_exchange_fmus_are_bit_for_bit_the_recorded_ones() {
    let Some(dir) = reference_fmus() else { return };
    let mut actual = Vec::new();
    for version in [2, 3] {
        for model in ["VanDerPol", "BouncingBall", "Dahlquist", "Stair"] {
            let folder = dir.join(format!("fmi{version}"));
            let m = fmu::open(
                &folder.join(format!("{model}.fmu")),
                Some(Interface::ModelExchange),
            )
            .unwrap();
            let (_, rows) = read_reference(&folder.join(format!("{model}_ref.csv")));
            let grid: Vec<f64> = rows.iter().map(|r| r[0]).collect();
            let p = m.info().default_vector();
            for (tol, options) in [
                ("default", SolverOptions::default()),
                (
                    "tight",
                    SolverOptions {
                        rtol: 1e-10,
                        atol: 1e-12,
                        max_steps: 1_000_000,
                        ..SolverOptions::default()
                    },
                ),
            ] {
                actual.push(
                    simulate(m, &p, &grid, &options).named(format!("fmi{version} {model} {tol}")),
                );
            }
        }
    }
    check(FMUS, &actual);
}
