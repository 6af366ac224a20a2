//! TLS and bearer-token authentication for calib's gRPC servers and clients.
//!
//! A server is secured by a [`ServerSecurity`] (certificate and key, token): [`ServerSecurity::apply`]
//! turns a `tonic` server builder into one serving TLS with the token required in front of
//! every service but health checks ([`auth`]). A client dials with a [`ClientSecurity`] (the
//! CA it trusts, the token it presents). [`failure`] puts a refused certificate or token in
//! words. The token never shows in logs or `Debug` output ([`token`]).

pub mod auth;
pub mod client;
pub mod error;
pub mod failure;
pub mod server;
pub mod tls;
pub mod token;

pub use client::{ClientSecurity, PresentToken, SecureChannel};
pub use error::SecurityError;
pub use server::{SecureServer, ServerSecurity};
pub use tls::{ServerTls, TrustedCa};
pub use token::{Token, TOKEN_ENV};
