//! The randomised benchmark of the diagnosis (`calib bench diagnose --random N --seed S`):
//! records of the Furuta rig drawn at random, made by the independent simulator
//! `tests/python/furuta_driven.py` (scipy, no code shared with the worker) or its wrapper
//! `furuta_extra_torque.py` (a cogging torque outside the library), each diagnosed under
//! search settings drawn from the robustness matrix's axes.
//!
//! Record `i` of seed `S` is drawn from its own generator (ChaCha8 seeded by `S` and `i`), so
//! a record is the same whatever else is drawn, and the draws are:
//!
//! - its category, by `i` modulo 10: clean (0, 1), one effect (2–6), two effects at once
//!   (7, 8), a cogging torque for discovery (9);
//! - each effect's kind, uniformly from every candidate of the library (on either joint or
//!   either output, the Coulomb frictions by holding the campaign's at 0), two distinct
//!   kinds for two effects, at most one of them a Coulomb friction;
//! - each effect's size, log-uniform over one decade from [`Kind::low`]: the size at which
//!   the effect changes the clean record (its frictions as they are) by a sum of squares of
//!   10⁴ σ² at the largest noise (4 mrad) and the less favourable of the start angles 20° and
//!   60°, or, for the measurement chain's effects, which nothing else absorbs, about
//!   2·10³ σ² (measured with the simulator: `docs/diagnosis.md`);
//! - the noise, uniform in 1–4 mrad (then 4096-count quantisation), the start angle of the
//!   pendulum uniform in 20–60°, and the noise's seed;
//! - the search: bounds (linear [0, 0.9] or log10 [1e-4, 0.9]), methods (Nelder–Mead,
//!   Nelder–Mead + Powell, or those and differential evolution) and starts (1 or 4);
//! - for a cogging record: `a sin(k φ)` on the arm, `k` uniform in 4–24, `a` uniform in
//!   2–8 mN·m.
//!
//! A record passes when the diagnosis selects exactly its effects ("nothing missing" for a
//! clean record) and ends within [`super::NOISE_FACTOR`] of the noise floor; a cogging record
//! when discovery proposes a term `sin(k·armJoint.phi)` of the right `k` on the arm and its
//! refit ends within that factor too.

use super::matrix::{parameter_toml, search_toml, BOUNDS, METHODS, STARTS};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::path::Path;

/// A kind of effect the library holds, as the independent simulator makes it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Kind {
    /// Short name, e.g. `viscous-arm`.
    pub name: &'static str,
    /// The simulator's option that sets its size.
    pub option: &'static str,
    /// The effect the diagnosis must select.
    pub effect: &'static str,
    /// The smallest size drawn; sizes are log-uniform over `[low, 10 low]`.
    pub low: f64,
    /// Whether the size's sign is drawn too.
    pub signed: bool,
    /// The friction the campaign holds at 0 (the record's own is the effect).
    pub hold: Option<&'static str>,
}

/// Every kind of effect of the library, on each joint and each output.
pub const KINDS: [Kind; 18] = [
    kind(
        "viscous-arm",
        "--arm-viscous",
        "viscous_friction.arm",
        1e-4,
        false,
    ),
    kind(
        "viscous-pendulum",
        "--pendulum-viscous",
        "viscous_friction.pendulum",
        1e-5,
        false,
    ),
    kind("drag-arm", "--arm-drag", "quadratic_drag.arm", 1e-4, false),
    kind(
        "drag-pendulum",
        "--pendulum-drag",
        "quadratic_drag.pendulum",
        1e-6,
        false,
    ),
    kind(
        "stiffness-arm",
        "--arm-stiffness",
        "stiffness.arm",
        3e-5,
        false,
    ),
    kind(
        "stiffness-pendulum",
        "--pendulum-stiffness",
        "stiffness.pendulum",
        2e-5,
        false,
    ),
    kind("bias-arm", "--arm-bias", "torque_bias.arm", 1e-5, true),
    kind(
        "bias-pendulum",
        "--pendulum-bias",
        "torque_bias.pendulum",
        1e-4,
        true,
    ),
    kind(
        "offset-arm",
        "--arm-offset",
        "offset(armJoint.phi)",
        3e-3,
        true,
    ),
    kind(
        "offset-pendulum",
        "--pendulum-offset",
        "offset(pendulumJoint.phi)",
        3e-3,
        true,
    ),
    kind("gain-arm", "--arm-gain", "gain(armJoint.phi)", 2e-2, true),
    kind(
        "gain-pendulum",
        "--pendulum-gain",
        "gain(pendulumJoint.phi)",
        1e-3,
        true,
    ),
    kind(
        "delay-arm",
        "--arm-delay",
        "delay(armJoint.phi)",
        1e-2,
        false,
    ),
    kind(
        "delay-pendulum",
        "--pendulum-delay",
        "delay(pendulumJoint.phi)",
        2e-3,
        false,
    ),
    kind("lag-arm", "--arm-lag", "lag(armJoint.phi)", 1e-2, false),
    kind(
        "lag-pendulum",
        "--pendulum-lag",
        "lag(pendulumJoint.phi)",
        2e-3,
        false,
    ),
    Kind {
        name: "coulomb-arm",
        option: "--arm-friction",
        effect: "coulomb_friction.arm",
        low: 3e-3,
        signed: false,
        hold: Some("armFriction"),
    },
    Kind {
        name: "coulomb-pendulum",
        option: "--pendulum-friction",
        effect: "coulomb_friction.pendulum",
        low: 3e-4,
        signed: false,
        hold: Some("pendulumFriction"),
    },
];

const fn kind(
    name: &'static str,
    option: &'static str,
    effect: &'static str,
    low: f64,
    signed: bool,
) -> Kind {
    Kind {
        name,
        option,
        effect,
        low,
        signed,
        hold: None,
    }
}

/// What a record holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Category {
    Clean,
    Single,
    Double,
    Cogging,
}

impl Category {
    pub fn name(self) -> &'static str {
        match self {
            Self::Clean => "clean",
            Self::Single => "one effect",
            Self::Double => "two effects",
            Self::Cogging => "cogging (discovery)",
        }
    }
}

/// One record of the benchmark and the search it is diagnosed with.
#[derive(Debug, Clone)]
pub struct Draw {
    pub index: usize,
    pub category: Category,
    /// The effects (index into [`KINDS`]) and their sizes.
    pub effects: Vec<(usize, f64)>,
    /// The cogging's periods per revolution and amplitude [N·m].
    pub cogging: Option<(u32, f64)>,
    /// Noise standard deviation [rad].
    pub noise: f64,
    /// Initial pendulum angle [rad], 0 upright.
    pub theta0: f64,
    pub noise_seed: u64,
    pub bounds: &'static str,
    pub methods: &'static str,
    pub starts: usize,
}

/// Record `index` of the benchmark of `seed`.
pub fn draw(seed: u64, index: usize) -> Draw {
    let mut rng =
        ChaCha8Rng::seed_from_u64(seed ^ (index as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15));
    let category = match index % 10 {
        0 | 1 => Category::Clean,
        2..=6 => Category::Single,
        7 | 8 => Category::Double,
        _ => Category::Cogging,
    };
    let count = match category {
        Category::Single => 1,
        Category::Double => 2,
        _ => 0,
    };
    let mut effects: Vec<(usize, f64)> = Vec::new();
    while effects.len() < count {
        let k = rng.random_range(0..KINDS.len());
        let kind = &KINDS[k];
        // Two distinct kinds, at most one a Coulomb friction: the campaign keeps a friction
        // free (with both held there would be nothing to calibrate).
        let clash = |e: usize| e == k || (KINDS[e].hold.is_some() && kind.hold.is_some());
        if effects.iter().any(|(e, _)| clash(*e)) {
            continue;
        }
        let mut size = kind.low * 10f64.powf(rng.random_range(0.0..1.0));
        if kind.signed && rng.random_bool(0.5) {
            size = -size;
        }
        effects.push((k, size));
    }
    let cogging = (category == Category::Cogging)
        .then(|| (rng.random_range(4..=24u32), rng.random_range(0.002..0.008)));
    Draw {
        index,
        category,
        effects,
        cogging,
        noise: rng.random_range(0.001..0.004),
        theta0: rng.random_range(20f64..60.0).to_radians(),
        noise_seed: rng.random_range(1..1_000_000),
        bounds: BOUNDS[rng.random_range(0..BOUNDS.len())],
        methods: METHODS[rng.random_range(0..METHODS.len())],
        starts: STARTS[rng.random_range(0..STARTS.len())],
    }
}

impl Draw {
    /// The effects the diagnosis must select, sorted.
    pub fn expected(&self) -> Vec<String> {
        let mut e: Vec<String> = self
            .effects
            .iter()
            .map(|(k, _)| KINDS[*k].effect.to_string())
            .collect();
        e.sort();
        e
    }

    /// What the record holds, in words (`viscous-arm 1.2e-3 + offset-arm -4.0e-3`).
    pub fn describe(&self) -> String {
        let mut parts: Vec<String> = self
            .effects
            .iter()
            .map(|(k, size)| format!("{} {size:.2e}", KINDS[*k].name))
            .collect();
        if let Some((k, a)) = self.cogging {
            parts.push(format!("cogging {a:.2e}·sin({k}φ)"));
        }
        if parts.is_empty() {
            parts.push("clean".into());
        }
        parts.join(" + ")
    }

    /// The simulator's arguments (after `--out FILE`): a free swing of 40 s.
    pub fn simulator_args(&self) -> Vec<String> {
        let mut args: Vec<String> = vec![
            "--no-torque".into(),
            "--stop".into(),
            "40".into(),
            "--seed".into(),
            self.noise_seed.to_string(),
            "--noise".into(),
            format!("{:e}", self.noise),
            "--theta0".into(),
            format!("{:e}", self.theta0),
        ];
        // `--option=value`: a negative value is not read as an option of its own.
        for (k, size) in &self.effects {
            args.push(format!("{}={size:e}", KINDS[*k].option));
        }
        if let Some((k, a)) = self.cogging {
            args.extend([
                "--cogging".into(),
                format!("{a:e}"),
                "--cogging-k".into(),
                k.to_string(),
            ]);
        }
        args
    }

    /// The script that makes the record: the cogging's wrapper or the simulator itself.
    pub fn script(&self) -> &'static str {
        if self.cogging.is_some() {
            "tests/python/furuta_extra_torque.py"
        } else {
            "tests/python/furuta_driven.py"
        }
    }

    /// The campaign diagnosed on the record `data`: both frictions free (but one the record
    /// holds as its effect, held at 0), the start angle known, fitted on 0–30 s and held out
    /// on 30–40 s.
    pub fn campaign(&self, data: &Path) -> String {
        let holds: Vec<&str> = self
            .effects
            .iter()
            .filter_map(|(k, _)| KINDS[*k].hold)
            .collect();
        let mut text = format!(
            r#"name = "random{index}"
[model]
name = "furuta"
stop_time = 40.0
[model.parameters]
theta0 = {theta0:?}
{holds}
[measurement]
file = "{data}"
time_column = "time_s"
[[outputs]]
model = "armJoint.phi"
measured = "arm_angle_rad"
[[outputs]]
model = "pendulumJoint.phi"
measured = "pendulum_angle_rad"
[window]
start = 0.0
stop = 30.0
[diagnosis]
holdout_start = 30.01
holdout_stop = 40.0
"#,
            index = self.index,
            theta0 = self.theta0,
            holds = holds
                .iter()
                .map(|h| format!("{h} = 0.0"))
                .collect::<Vec<_>>()
                .join("\n"),
            data = data.display(),
        );
        for (name, nominal) in [("armFriction", 0.012), ("pendulumFriction", 0.002)] {
            if !holds.contains(&name) {
                text.push_str(&parameter_toml(name, nominal, self.bounds, 1e-4));
            }
        }
        text.push_str(&search_toml(self.methods, self.starts));
        text
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_record_is_drawn_the_same_whatever_else_is_drawn() {
        let a = draw(7, 13);
        let _ = draw(7, 12);
        let b = draw(7, 13);
        assert_eq!(format!("{a:?}"), format!("{b:?}"));
        assert_ne!(format!("{:?}", draw(8, 13)), format!("{a:?}"));
    }

    #[test]
    fn draws_cover_every_category_and_kind_within_their_ranges() {
        let draws: Vec<Draw> = (0..400).map(|i| draw(1, i)).collect();
        let count = |c: Category| draws.iter().filter(|d| d.category == c).count();
        assert_eq!(
            [
                Category::Clean,
                Category::Single,
                Category::Double,
                Category::Cogging
            ]
            .map(count),
            [80, 200, 80, 40]
        );
        for (k, kind) in KINDS.iter().enumerate() {
            let sizes: Vec<f64> = draws
                .iter()
                .flat_map(|d| d.effects.iter().filter(|(e, _)| *e == k).map(|(_, s)| *s))
                .collect();
            assert!(!sizes.is_empty(), "{} never drawn", kind.name);
            assert!(sizes
                .iter()
                .all(|s| (kind.low..=10.0 * kind.low).contains(&s.abs())));
        }
        for d in &draws {
            assert!((0.001..0.004).contains(&d.noise));
            assert!((20f64.to_radians()..60f64.to_radians()).contains(&d.theta0));
            let expected = d.expected();
            assert_eq!(expected.len(), d.effects.len(), "distinct effects");
            if let Some((k, a)) = d.cogging {
                assert!((4..=24).contains(&k) && (0.002..0.008).contains(&a));
            }
        }
    }

    #[test]
    fn a_campaign_holds_the_coulomb_friction_a_record_carries_as_its_effect() {
        let d = Draw {
            effects: vec![(16, 0.01), (0, 1e-3)],
            ..draw(1, 7)
        };
        let text = d.campaign(Path::new("/r.csv"));
        assert!(text.contains("armFriction = 0.0"));
        assert!(!text.contains("name = \"armFriction\""));
        assert!(text.contains("name = \"pendulumFriction\""));
        assert!(text.contains(&format!("theta0 = {:?}", d.theta0)));
        assert_eq!(
            d.expected(),
            ["coulomb_friction.arm", "viscous_friction.arm"]
        );
    }
}
