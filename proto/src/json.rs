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

#[cfg(test)]
mod tests {
    use crate::v1::{DiagnosisFit, SensitivityStatistics};

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
