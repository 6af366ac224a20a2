//! The hosted models. Each lives in its own module and implements [`crate::Model`].

pub mod furuta;
pub mod hx;

use crate::effects::WithOutputEffects;
use crate::Model;
use std::sync::OnceLock;

/// Every hosted model, in the order `calib models` lists them, each with the per-output
/// measurement effects of [`WithOutputEffects`].
pub fn all() -> &'static [Box<dyn Model>] {
    static MODELS: OnceLock<Vec<Box<dyn Model>>> = OnceLock::new();
    MODELS.get_or_init(|| {
        vec![
            Box::new(WithOutputEffects::new(furuta::Furuta::new())),
            Box::new(WithOutputEffects::new(hx::highfi())),
            Box::new(WithOutputEffects::new(hx::lowfi())),
        ]
    })
}

/// The hosted model called `name`, or an FMU opened in this process under that name
/// ([`crate::fmu`]).
pub fn find(name: &str) -> Option<&'static dyn Model> {
    all()
        .iter()
        .find(|m| m.info().name == name)
        .map(|m| m.as_ref())
        .or_else(|| crate::fmu::find(name))
}
