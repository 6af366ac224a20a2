//! The library of candidate functions a missing torque is regressed on: functions of the
//! smoothed states and the inputs, each with the formula text an effect would carry.
//!
//! - monomials of every angle and speed up to [`LibraryOptions::degree`] (3): a constant,
//!   stiffness-like and drag-like terms, their products (`q·ω²`…);
//! - per speed `|ω|·ω` (quadratic drag) and `sign(ω)` (Coulomb friction);
//! - every input, linearly (a gain error);
//! - per angle `sin(m·q)` and `cos(m·q)` for `m = 1..M` (cogging, a position-dependent load,
//!   an unbalance), [`LibraryOptions::harmonics`] = 40 by default. Which `m` the record can
//!   show is not told: terms the smoothing hides (their filtered column keeps less than
//!   [`LibraryOptions::min_passed`] of its size) are dropped where the columns are built.

/// What kind of function a candidate is; harmonics pair up (a phase is unknown).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    Monomial,
    Drag,
    Sign,
    Input,
    Harmonic { angle: usize, m: usize, sine: bool },
}

/// One candidate function: its formula text and its values at every sample.
#[derive(Debug, Clone)]
pub struct Candidate {
    pub formula: String,
    pub kind: Kind,
    pub values: Vec<f64>,
}

#[derive(Debug, Clone, Copy)]
pub struct LibraryOptions {
    pub degree: usize,
    pub harmonics: usize,
    pub min_passed: f64,
}

impl Default for LibraryOptions {
    fn default() -> Self {
        Self {
            degree: 3,
            harmonics: 40,
            min_passed: 0.1,
        }
    }
}

/// Every candidate on the given series: `angles` and `speeds` (smoothed, named as formulas
/// name them), `inputs`.
pub fn candidates(
    angles: &[(String, Vec<f64>)],
    speeds: &[(String, Vec<f64>)],
    inputs: &[(String, Vec<f64>)],
    options: &LibraryOptions,
) -> Vec<Candidate> {
    let n = angles.first().map_or(0, |a| a.1.len());
    let mut out = Vec::new();
    let variables: Vec<&(String, Vec<f64>)> = angles.iter().chain(speeds).collect();
    for powers in exponents(variables.len(), options.degree) {
        let mut names = Vec::new();
        let mut values = vec![1.0; n];
        for (v, &p) in variables.iter().zip(&powers) {
            for _ in 0..p {
                names.push(v.0.clone());
                for (x, y) in values.iter_mut().zip(&v.1) {
                    *x *= y;
                }
            }
        }
        let formula = if names.is_empty() {
            "1".to_string()
        } else {
            names.join(" * ")
        };
        out.push(Candidate {
            formula,
            kind: Kind::Monomial,
            values,
        });
    }
    for (name, w) in speeds {
        out.push(Candidate {
            formula: format!("abs({name}) * {name}"),
            kind: Kind::Drag,
            values: w.iter().map(|w| w.abs() * w).collect(),
        });
        out.push(Candidate {
            formula: format!("sign({name})"),
            kind: Kind::Sign,
            values: w.iter().map(|w| sign(*w)).collect(),
        });
    }
    for (name, u) in inputs {
        out.push(Candidate {
            formula: name.clone(),
            kind: Kind::Input,
            values: u.clone(),
        });
    }
    for (a, (name, q)) in angles.iter().enumerate() {
        for m in 1..=options.harmonics {
            let argument = if m == 1 {
                name.clone()
            } else {
                format!("{m} * {name}")
            };
            for sine in [true, false] {
                let f = if sine { f64::sin } else { f64::cos };
                out.push(Candidate {
                    formula: format!("{}({argument})", if sine { "sin" } else { "cos" }),
                    kind: Kind::Harmonic { angle: a, m, sine },
                    values: q.iter().map(|q| f(m as f64 * q)).collect(),
                });
            }
        }
    }
    out
}

fn sign(x: f64) -> f64 {
    if x > 0.0 {
        1.0
    } else if x < 0.0 {
        -1.0
    } else {
        0.0
    }
}

/// Every vector of `k` non-negative powers with a sum of at most `degree`, by total degree.
fn exponents(k: usize, degree: usize) -> Vec<Vec<usize>> {
    let mut out = Vec::new();
    for total in 0..=degree {
        let mut current = vec![0; k];
        fill(&mut current, 0, total, &mut out);
    }
    out
}

fn fill(current: &mut Vec<usize>, at: usize, left: usize, out: &mut Vec<Vec<usize>>) {
    if at + 1 == current.len() || current.is_empty() {
        if let Some(last) = current.last_mut() {
            *last = left;
        }
        if current.is_empty() && left > 0 {
            return;
        }
        out.push(current.clone());
        return;
    }
    for p in (0..=left).rev() {
        current[at] = p;
        fill(current, at + 1, left - p, out);
    }
    current[at] = 0;
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn monomials_are_counted_and_named() {
        // 4 variables up to degree 3: C(7, 3) = 35 monomials, the constant first.
        assert_eq!(exponents(4, 3).len(), 35);
        let s = |n: &str, v: Vec<f64>| (n.to_string(), v);
        let lib = candidates(
            &[s("armJoint.phi", vec![2.0])],
            &[s("armJoint.w", vec![-3.0])],
            &[s("armTorque", vec![0.5])],
            &LibraryOptions {
                degree: 2,
                harmonics: 2,
                min_passed: 0.1,
            },
        );
        let names: Vec<&str> = lib.iter().map(|c| c.formula.as_str()).collect();
        assert_eq!(
            names,
            [
                "1",
                "armJoint.phi",
                "armJoint.w",
                "armJoint.phi * armJoint.phi",
                "armJoint.phi * armJoint.w",
                "armJoint.w * armJoint.w",
                "abs(armJoint.w) * armJoint.w",
                "sign(armJoint.w)",
                "armTorque",
                "sin(armJoint.phi)",
                "cos(armJoint.phi)",
                "sin(2 * armJoint.phi)",
                "cos(2 * armJoint.phi)",
            ]
        );
        let value = |f: &str| lib.iter().find(|c| c.formula == f).unwrap().values[0];
        assert_eq!(value("armJoint.phi * armJoint.w"), -6.0);
        assert_eq!(value("abs(armJoint.w) * armJoint.w"), -9.0);
        assert_eq!(value("sign(armJoint.w)"), -1.0);
        assert_eq!(value("sin(2 * armJoint.phi)"), 4.0f64.sin());
    }
}
