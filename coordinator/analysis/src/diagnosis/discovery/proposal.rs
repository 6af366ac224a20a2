//! What discovery proposes: an effect in the campaign file's syntax, never added by itself.

use serde::Serialize;

/// One parameter of a proposed effect (a campaign parameter `<effect>.<name>` once added).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct EffectParameter {
    pub name: String,
    pub nominal: f64,
    pub min: f64,
    pub max: f64,
}

/// One term the regression kept: its function, the parameter multiplying it, the estimate
/// and its 95% interval.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FoundTerm {
    pub function: String,
    pub parameter: String,
    pub estimate: f64,
    pub ci_low: f64,
    pub ci_high: f64,
}

/// A harmonic found as a sine and a cosine of one multiple of an angle: its amplitude
/// `sqrt(a² + b²)` with a 95% interval (delta method) and its phase.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FoundHarmonic {
    pub angle: String,
    pub multiple: usize,
    pub amplitude: f64,
    pub ci_low: f64,
    pub ci_high: f64,
    /// `c` in `amplitude · sin(m·q + c)` [rad].
    pub phase: f64,
}

/// A proposed user-defined effect: a generalized torque on a joint given by a formula.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct DiscoveredEffect {
    pub name: String,
    /// The joint the torque acts on (`torque = "armJoint"`).
    pub place: String,
    pub formula: String,
    pub parameters: Vec<EffectParameter>,
    pub terms: Vec<FoundTerm>,
    pub harmonics: Vec<FoundHarmonic>,
}

/// How far a proposed parameter's bounds reach beyond its 95% interval: the interval's
/// half-width times this on either side of the estimate.
pub const BOUND_WIDENING: f64 = 3.0;

impl DiscoveredEffect {
    /// The `[[effects]]` block a campaign file would hold.
    pub fn to_toml(&self) -> String {
        let mut s = String::from("[[effects]]\n");
        s.push_str(&format!("name = {}\n", quoted(&self.name)));
        s.push_str(&format!("torque = {}\n", quoted(&self.place)));
        s.push_str(&format!("formula = {}\n", quoted(&self.formula)));
        s.push_str("parameters = [\n");
        for p in &self.parameters {
            s.push_str(&format!(
                "  {{ name = {}, nominal = {}, min = {}, max = {} }},\n",
                quoted(&p.name),
                number(p.nominal),
                number(p.min),
                number(p.max)
            ));
        }
        s.push_str("]\n");
        s
    }
}

/// A TOML basic string.
fn quoted(text: &str) -> String {
    toml::Value::String(text.to_string()).to_string()
}

/// Five significant digits, enough for a start point and bounds.
fn number(x: f64) -> String {
    let text = format!("{x:.4e}");
    let parsed: f64 = text.parse().unwrap_or(x);
    let plain = format!("{parsed}");
    if plain.len() <= 12 {
        if plain.contains('.') || plain.contains('e') {
            plain
        } else {
            format!("{plain}.0")
        }
    } else {
        text
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_toml_block_reads_back() {
        let effect = DiscoveredEffect {
            name: "discovered.armJoint".into(),
            place: "armJoint".into(),
            formula: "a1 * sin(8 * armJoint.phi) + b1 * cos(8 * armJoint.phi)".into(),
            parameters: vec![
                EffectParameter {
                    name: "a1".into(),
                    nominal: 0.0059,
                    min: 0.0041,
                    max: 0.0077,
                },
                EffectParameter {
                    name: "b1".into(),
                    nominal: -1.234567e-5,
                    min: -0.002,
                    max: 0.002,
                },
            ],
            terms: vec![],
            harmonics: vec![],
        };
        let text = effect.to_toml();
        let value: toml::Value = toml::from_str(&text).unwrap();
        let e = &value["effects"][0];
        assert_eq!(e["name"].as_str(), Some("discovered.armJoint"));
        assert_eq!(e["torque"].as_str(), Some("armJoint"));
        assert_eq!(e["formula"].as_str(), Some(effect.formula.as_str()));
        let p = e["parameters"].as_array().unwrap();
        assert_eq!(p[0]["nominal"].as_float(), Some(0.0059));
        assert_eq!(p[1]["nominal"].as_float(), Some(-1.2346e-5));
        assert_eq!(p[1]["max"].as_float(), Some(0.002));
    }
}
