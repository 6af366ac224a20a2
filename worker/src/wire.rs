//! User-defined effects as the protocol carries them (`UserEffect` of simulator.proto).

use calib_model::user_effects::{place_of, EffectError, UserEffect, UserParameter};
use calib_model::PlaceKind;
use calib_proto::v1 as proto;

/// The definition a request carries as effect `i`.
pub fn from_proto(i: usize, e: &proto::UserEffect) -> Result<UserEffect, EffectError> {
    let given = |s: &str| (!s.is_empty()).then(|| s.to_string());
    let (torque, output) = (given(&e.torque), given(&e.output));
    let (kind, place) = place_of(i, torque.as_deref(), output.as_deref())?;
    Ok(UserEffect {
        name: e.name.clone(),
        kind,
        place,
        formula: e.formula.clone(),
        parameters: e
            .parameters
            .iter()
            .map(|p| UserParameter {
                name: p.name.clone(),
                nominal: p.nominal,
                min: p.min,
                max: p.max,
            })
            .collect(),
    })
}

/// The definition as a request carries it.
pub fn to_proto(e: &UserEffect) -> proto::UserEffect {
    let (torque, output) = match e.kind {
        PlaceKind::Torque => (e.place.clone(), String::new()),
        PlaceKind::Output => (String::new(), e.place.clone()),
    };
    proto::UserEffect {
        name: e.name.clone(),
        torque,
        output,
        formula: e.formula.clone(),
        parameters: e
            .parameters
            .iter()
            .map(|p| proto::UserEffectParameter {
                name: p.name.clone(),
                nominal: p.nominal,
                min: p.min,
                max: p.max,
            })
            .collect(),
    }
}

/// Every definition a request carries.
pub fn all_from_proto(effects: &[proto::UserEffect]) -> Result<Vec<UserEffect>, EffectError> {
    effects
        .iter()
        .enumerate()
        .map(|(i, e)| from_proto(i, e))
        .collect()
}
