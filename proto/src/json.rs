//! JSON forms of fields the messages' serde derive cannot take from their proto shape: the
//! reports' messages read and write the JSON files the commands write.

use crate::v1::NumberRow;
use serde::{Deserialize, Deserializer, Serialize, Serializer};

/// Numbers where JSON may hold null for a number that is not finite: null reads as NaN
/// (and NaN writes as null, as serde_json writes any non-finite number).
pub fn numbers<'de, D: Deserializer<'de>>(d: D) -> Result<Vec<f64>, D::Error> {
    let values = Vec::<Option<f64>>::deserialize(d)?;
    Ok(values.into_iter().map(|v| v.unwrap_or(f64::NAN)).collect())
}

/// A matrix as a list of lists of numbers (null for NaN), one list per row.
pub mod rows {
    use super::*;

    pub fn serialize<S: Serializer>(rows: &[NumberRow], s: S) -> Result<S::Ok, S::Error> {
        let lists: Vec<&Vec<f64>> = rows.iter().map(|r| &r.values).collect();
        lists.serialize(s)
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Vec<NumberRow>, D::Error> {
        let lists = Vec::<Vec<Option<f64>>>::deserialize(d)?;
        Ok(lists
            .into_iter()
            .map(|row| NumberRow {
                values: row.into_iter().map(|v| v.unwrap_or(f64::NAN)).collect(),
            })
            .collect())
    }
}

/// A module that writes an enum field by its name in the proto (`CAMPAIGN_PHASE_FINISHED`),
/// as the proto's JSON mapping does, and reads it by name or by number.
macro_rules! by_name {
    ($module:ident, $enum:ty) => {
        pub mod $module {
            use serde::{Deserialize, Deserializer, Serializer};

            pub fn serialize<S: Serializer>(value: &i32, s: S) -> Result<S::Ok, S::Error> {
                match <$enum>::try_from(*value) {
                    Ok(known) => s.serialize_str(known.as_str_name()),
                    Err(_) => s.serialize_i32(*value),
                }
            }

            pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<i32, D::Error> {
                #[derive(Deserialize)]
                #[serde(untagged)]
                enum NameOrNumber {
                    Name(String),
                    Number(i32),
                }
                match NameOrNumber::deserialize(d)? {
                    NameOrNumber::Number(n) => Ok(n),
                    NameOrNumber::Name(name) => <$enum>::from_str_name(&name)
                        .map(|v| v as i32)
                        .ok_or_else(|| serde::de::Error::custom(format!("no such value: {name}"))),
                }
            }
        }
    };
}

by_name!(campaign_phase, crate::v1::CampaignPhase);
by_name!(interpolation, crate::v1::Interpolation);

#[cfg(test)]
mod tests {
    use crate::v1::{CampaignState, DiagnosisFit, SensitivityStatistics};

    #[test]
    fn a_phase_is_written_by_name_and_read_by_name_or_number() {
        let state = CampaignState {
            phase: crate::v1::CampaignPhase::Finished as i32,
            ..Default::default()
        };
        let json = serde_json::to_value(&state).unwrap();
        assert_eq!(json["phase"], "CAMPAIGN_PHASE_FINISHED");
        let back: CampaignState = serde_json::from_value(json).unwrap();
        assert_eq!(back.phase, state.phase);
        let by_number: CampaignState =
            serde_json::from_value(serde_json::json!({"phase": 3})).unwrap();
        assert_eq!(by_number.phase(), crate::v1::CampaignPhase::Failed);
        assert!(
            serde_json::from_value::<CampaignState>(serde_json::json!({"phase": "DONE"})).is_err()
        );
    }

    #[test]
    fn a_correlation_matrix_reads_and_writes_as_a_list_of_lists() {
        let json = serde_json::json!({"correlation": [[1.0, -0.5], [-0.5, null]]});
        let fit: DiagnosisFit = serde_json::from_value(json).unwrap();
        assert_eq!(fit.correlation[0].values, vec![1.0, -0.5]);
        assert!(fit.correlation[1].values[1].is_nan());
        let back = serde_json::to_value(&fit).unwrap();
        assert_eq!(
            back["correlation"],
            serde_json::json!([[1.0, -0.5], [-0.5, null]])
        );
    }

    #[test]
    fn an_interval_with_a_null_end_reads_as_nan() {
        let json = serde_json::json!({"first_ci": [null, 0.5], "mu": null});
        let s: SensitivityStatistics = serde_json::from_value(json).unwrap();
        assert!(s.first_ci[0].is_nan() && s.first_ci[1] == 0.5);
        assert_eq!(s.mu, None);
    }
}
