//! `modelDescription.xml` of FMI 2.0 and 3.0: what calib needs of it — the interfaces and
//! their model identifiers, the real-valued variables (name, value reference, causality,
//! variability, start, unit, min, max), the number of continuous states and of event
//! indicators, and the default experiment.

use super::FmuError;
use std::collections::HashMap;

/// FMI version of an FMU.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FmiVersion {
    V2,
    V3,
}

/// How an FMU is run.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Interface {
    /// calib integrates the FMU's derivatives (Dormand–Prince, with its event indicators).
    ModelExchange,
    /// The FMU integrates itself; calib calls `doStep` from one output time to the next.
    CoSimulation,
}

impl Interface {
    pub fn name(self) -> &'static str {
        match self {
            Interface::ModelExchange => "Model Exchange",
            Interface::CoSimulation => "Co-Simulation",
        }
    }
}

/// The type of a scalar variable calib reads.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    /// FMI 2.0 `Real`, FMI 3.0 `Float64`.
    Real,
    /// FMI 2.0 `Integer`, FMI 3.0 `Int32`.
    Integer,
    /// FMI 2.0 and 3.0 `Boolean`.
    Boolean,
}

/// A scalar variable of a type calib reads (parameters are real ones only).
#[derive(Debug, Clone, PartialEq)]
pub struct Variable {
    pub name: String,
    pub kind: Kind,
    pub value_reference: u32,
    /// `parameter`, `calculatedParameter`, `input`, `output`, `local`, `independent`, ...
    pub causality: String,
    /// `constant`, `fixed`, `tunable`, `discrete`, `continuous`.
    pub variability: String,
    pub start: Option<f64>,
    pub unit: String,
    pub min: Option<f64>,
    pub max: Option<f64>,
    pub description: String,
}

/// A declared type's unit, min and max.
type DeclaredType = (String, Option<f64>, Option<f64>);

/// What calib reads of a model description.
#[derive(Debug, Clone)]
pub struct Description {
    pub version: FmiVersion,
    pub model_name: String,
    pub description: String,
    /// FMI 2.0 `guid`, FMI 3.0 `instantiationToken`.
    pub token: String,
    /// Model identifier (the shared library's name) of the Model Exchange interface.
    pub model_exchange: Option<String>,
    /// Model identifier of the Co-Simulation interface.
    pub co_simulation: Option<String>,
    pub variables: Vec<Variable>,
    pub continuous_states: usize,
    pub event_indicators: usize,
    /// The `DefaultExperiment`'s times, step and relative tolerance, as the FMU gives them.
    pub default_start_time: Option<f64>,
    pub default_stop_time: Option<f64>,
    pub default_step_size: Option<f64>,
    pub default_tolerance: Option<f64>,
}

impl Description {
    /// Parse a model description of FMI 2.0 or 3.0.
    pub fn parse(xml: &str) -> Result<Self, FmuError> {
        let doc = roxmltree::Document::parse(xml)
            .map_err(|e| FmuError::Description(format!("not XML: {e}")))?;
        let root = doc.root_element();
        if root.tag_name().name() != "fmiModelDescription" {
            return Err(FmuError::Description(format!(
                "root element is <{}>, not <fmiModelDescription>",
                root.tag_name().name()
            )));
        }
        let fmi_version = root.attribute("fmiVersion").unwrap_or("");
        let version = if fmi_version.starts_with("2.") {
            FmiVersion::V2
        } else if fmi_version.starts_with("3.") {
            FmiVersion::V3
        } else {
            return Err(FmuError::Description(format!(
                "fmiVersion `{fmi_version}` is neither 2.0 nor 3.0"
            )));
        };
        let child = |name: &str| root.children().find(|n| n.has_tag_name(name));
        let identifier = |name: &str| {
            child(name)
                .and_then(|n| n.attribute("modelIdentifier"))
                .map(str::to_string)
        };

        let types = declared_types(version, child("TypeDefinitions"))?;
        let variables = match child("ModelVariables") {
            Some(vars) => variables(version, vars, &types)?,
            None => Vec::new(),
        };

        let (continuous_states, event_indicators) = counts(version, root, child("ModelStructure"));
        let experiment = child("DefaultExperiment");
        Ok(Description {
            version,
            model_name: root.attribute("modelName").unwrap_or("").to_string(),
            description: root.attribute("description").unwrap_or("").to_string(),
            token: root
                .attribute(match version {
                    FmiVersion::V2 => "guid",
                    FmiVersion::V3 => "instantiationToken",
                })
                .unwrap_or("")
                .to_string(),
            model_exchange: identifier("ModelExchange"),
            co_simulation: identifier("CoSimulation"),
            variables,
            continuous_states,
            event_indicators,
            default_start_time: match experiment {
                Some(e) => number(e, "startTime")?,
                None => None,
            },
            default_stop_time: match experiment {
                Some(e) => number(e, "stopTime")?,
                None => None,
            },
            default_step_size: match experiment {
                Some(e) => number(e, "stepSize")?,
                None => None,
            },
            default_tolerance: match experiment {
                Some(e) => number(e, "tolerance")?,
                None => None,
            },
        })
    }

    /// Real parameters a campaign may set: causality `parameter`, variability `fixed` or
    /// `tunable` (both are set before initialisation, which every simulation starts with).
    pub fn parameters(&self) -> impl Iterator<Item = &Variable> {
        self.variables.iter().filter(|v| {
            v.kind == Kind::Real
                && v.causality == "parameter"
                && (v.variability == "fixed" || v.variability == "tunable")
        })
    }

    /// Variables a simulation may drive: causality `input`, of a type calib sets (Real /
    /// Float64, Integer / Int32, Boolean).
    pub fn inputs(&self) -> impl Iterator<Item = &Variable> {
        self.variables.iter().filter(|v| v.causality == "input")
    }

    /// Variables a simulation can report (integers and booleans as numbers): outputs first, then every other variable
    /// that is neither a parameter, a constant nor the independent variable.
    pub fn observables(&self) -> Vec<&Variable> {
        let other = |v: &&Variable| {
            !matches!(
                v.causality.as_str(),
                "parameter" | "calculatedParameter" | "independent" | "structuralParameter"
            ) && v.variability != "constant"
        };
        let mut list: Vec<&Variable> = self
            .variables
            .iter()
            .filter(|v| v.causality == "output")
            .collect();
        list.extend(
            self.variables
                .iter()
                .filter(other)
                .filter(|v| v.causality != "output"),
        );
        list
    }
}

/// The number in attribute `attr` of `n`, if it has one.
fn number(n: roxmltree::Node, attr: &str) -> Result<Option<f64>, FmuError> {
    n.attribute(attr)
        .map(|v| {
            v.trim().parse::<f64>().map_err(|_| {
                FmuError::Description(format!(
                    "`{attr}` of <{}> is not a number: `{v}`",
                    n.tag_name().name()
                ))
            })
        })
        .transpose()
}

/// Declared types: the unit, min and max a variable of each inherits.
fn declared_types(
    version: FmiVersion,
    definitions: Option<roxmltree::Node>,
) -> Result<HashMap<String, DeclaredType>, FmuError> {
    let mut types: HashMap<String, DeclaredType> = HashMap::new();
    if let Some(defs) = definitions {
        for t in defs.children().filter(|n| n.is_element()) {
            let Some(name) = t.attribute("name") else {
                continue;
            };
            // FMI 2.0: <SimpleType name><Real unit min max/></SimpleType>;
            // FMI 3.0: <Float64Type name unit min max/>.
            let holder = match version {
                FmiVersion::V2 => t.children().find(|n| n.has_tag_name("Real")),
                FmiVersion::V3 => t.has_tag_name("Float64Type").then_some(t),
            };
            if let Some(h) = holder {
                types.insert(
                    name.to_string(),
                    (
                        h.attribute("unit").unwrap_or("").to_string(),
                        number(h, "min")?,
                        number(h, "max")?,
                    ),
                );
            }
        }
    }
    Ok(types)
}

/// The scalar variables of `<ModelVariables>` of the types calib reads (Real / Float64,
/// Integer / Int32, Boolean).
fn variables(
    version: FmiVersion,
    vars: roxmltree::Node,
    types: &HashMap<String, DeclaredType>,
) -> Result<Vec<Variable>, FmuError> {
    let mut variables = Vec::new();
    for v in vars.children().filter(|n| n.is_element()) {
        // FMI 2.0: <ScalarVariable ...><Real start unit .../></ScalarVariable>;
        // FMI 3.0: <Float64 name ... start unit .../>.
        let holder = match version {
            FmiVersion::V2 => {
                v.children()
                    .find(|n| n.is_element())
                    .and_then(|h| match h.tag_name().name() {
                        "Real" => Some((h, Kind::Real)),
                        "Integer" => Some((h, Kind::Integer)),
                        "Boolean" => Some((h, Kind::Boolean)),
                        _ => None,
                    })
            }
            FmiVersion::V3 => match v.tag_name().name() {
                "Float64" => Some((v, Kind::Real)),
                "Int32" => Some((v, Kind::Integer)),
                "Boolean" => Some((v, Kind::Boolean)),
                _ => None,
            },
        };
        let Some((h, kind)) = holder else {
            continue;
        };
        let name = v.attribute("name").unwrap_or("").to_string();
        let vr = v
            .attribute("valueReference")
            .and_then(|s| s.trim().parse::<u32>().ok())
            .ok_or_else(|| {
                FmuError::Description(format!("variable `{name}` has no valid valueReference"))
            })?;
        let inherited = h
            .attribute("declaredType")
            .and_then(|t| types.get(t))
            .cloned()
            .unwrap_or_default();
        // FMI 3.0 arrays (<Dimension>) are not scalars: leave them out.
        if v.children().any(|n| n.has_tag_name("Dimension")) {
            continue;
        }
        let start = match h.attribute("start").map(str::trim) {
            Some("true") => Some(1.0),
            Some("false") => Some(0.0),
            Some(s) => s.parse::<f64>().ok(),
            None => None,
        };
        variables.push(Variable {
            name,
            kind,
            value_reference: vr,
            causality: v.attribute("causality").unwrap_or("local").to_string(),
            variability: v
                .attribute("variability")
                .unwrap_or("continuous")
                .to_string(),
            start,
            unit: h
                .attribute("unit")
                .map(str::to_string)
                .unwrap_or(inherited.0),
            min: number(h, "min")?.or(inherited.1),
            max: number(h, "max")?.or(inherited.2),
            description: v.attribute("description").unwrap_or("").to_string(),
        });
    }
    Ok(variables)
}

/// The number of continuous states and of event indicators.
fn counts(
    version: FmiVersion,
    root: roxmltree::Node,
    structure: Option<roxmltree::Node>,
) -> (usize, usize) {
    match version {
        FmiVersion::V2 => {
            let states = structure
                .and_then(|s| s.children().find(|n| n.has_tag_name("Derivatives")))
                .map_or(0, |d| {
                    d.children().filter(|n| n.has_tag_name("Unknown")).count()
                });
            let indicators = root
                .attribute("numberOfEventIndicators")
                .and_then(|s| s.trim().parse().ok())
                .unwrap_or(0);
            (states, indicators)
        }
        FmiVersion::V3 => {
            let count = |tag: &str| {
                structure.map_or(0, |s| s.children().filter(|n| n.has_tag_name(tag)).count())
            };
            (count("ContinuousStateDerivative"), count("EventIndicator"))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const V2: &str = r#"<?xml version="1.0"?>
<fmiModelDescription fmiVersion="2.0" modelName="M" guid="{g}" numberOfEventIndicators="1">
  <ModelExchange modelIdentifier="M"/>
  <UnitDefinitions><Unit name="m"/></UnitDefinitions>
  <TypeDefinitions><SimpleType name="Position"><Real unit="m" min="0"/></SimpleType></TypeDefinitions>
  <DefaultExperiment stopTime="3"/>
  <ModelVariables>
    <ScalarVariable name="time" valueReference="0" causality="independent"><Real/></ScalarVariable>
    <ScalarVariable name="h" valueReference="1" causality="output" variability="continuous"><Real start="1" declaredType="Position"/></ScalarVariable>
    <ScalarVariable name="der(h)" valueReference="2"><Real derivative="2"/></ScalarVariable>
    <ScalarVariable name="n" valueReference="4" causality="parameter" variability="fixed"><Integer start="3"/></ScalarVariable>
    <ScalarVariable name="e" valueReference="3" causality="parameter" variability="tunable"><Real start="0.7" min="0.5" max="1"/></ScalarVariable>
  </ModelVariables>
  <ModelStructure><Outputs><Unknown index="2"/></Outputs><Derivatives><Unknown index="3"/></Derivatives></ModelStructure>
</fmiModelDescription>"#;

    #[test]
    fn a_version_2_description_gives_parameters_outputs_units_and_bounds() {
        let d = Description::parse(V2).unwrap();
        assert_eq!(d.version, FmiVersion::V2);
        assert_eq!(d.model_exchange.as_deref(), Some("M"));
        assert_eq!(d.co_simulation, None);
        assert_eq!((d.continuous_states, d.event_indicators), (1, 1));
        assert_eq!(d.default_stop_time, Some(3.0));
        let params: Vec<_> = d.parameters().collect();
        assert_eq!(params.len(), 1, "the integer parameter is not a real one");
        assert_eq!(
            (
                params[0].name.as_str(),
                params[0].start,
                params[0].min,
                params[0].max
            ),
            ("e", Some(0.7), Some(0.5), Some(1.0))
        );
        let obs: Vec<_> = d.observables().iter().map(|v| v.name.clone()).collect();
        assert_eq!(obs, ["h", "der(h)"]);
        let h = d.observables()[0];
        assert_eq!((h.unit.as_str(), h.min), ("m", Some(0.0)));
    }

    #[test]
    fn other_versions_and_other_documents_are_refused() {
        let e = Description::parse(&V2.replace("2.0", "1.0")).unwrap_err();
        assert!(e.to_string().contains("neither 2.0 nor 3.0"), "{e}");
        let e = Description::parse("<a/>").unwrap_err();
        assert!(e.to_string().contains("<fmiModelDescription>"), "{e}");
    }
}
