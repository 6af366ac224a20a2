//! What the residuals of a fit tell, shared by the diagnosis, the profiles and the local
//! sensitivities: whether they are white and how large the noise is ([`whiteness`]), how the
//! outputs move with the parameters ([`jacobian`], by finite differences through the
//! simulator), linearised least squares on those columns ([`linear`]) and the confidence
//! intervals that follow ([`uncertainty`]).

pub mod jacobian;
pub mod linear;
pub mod uncertainty;
pub mod whiteness;
