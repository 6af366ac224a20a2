//! The security options: the certificate a server presents, the CA a client trusts, and
//! the cluster's bearer token.

use super::Failure;
use calib_security::{ClientSecurity, ServerSecurity, Token, TrustedCa};
use std::path::PathBuf;

/// TLS for a server.
#[derive(clap::Args, Debug, Clone)]
pub struct ServeArgs {
    /// Serve over TLS with this certificate (PEM, the chain from the server's own
    /// certificate up); clients then dial https://.
    #[arg(long, value_name = "FILE", requires = "tls_key")]
    pub tls_cert: Option<PathBuf>,
    /// The private key of --tls-cert (PEM).
    #[arg(long, value_name = "FILE", requires = "tls_cert")]
    pub tls_key: Option<PathBuf>,
}

/// What a client trusts and presents; the token is also what a server requires.
#[derive(clap::Args, Debug, Clone)]
pub struct DialArgs {
    /// Trust this CA (PEM) for https:// servers [default: the system's root certificates].
    #[arg(long, value_name = "FILE")]
    pub tls_ca: Option<PathBuf>,
    /// The cluster's bearer token, in a file: servers refuse requests without it
    /// (UNAUTHENTICATED; health checks stay open), clients present it [default: the
    /// CALIB_TOKEN environment variable; none when unset].
    #[arg(long, value_name = "FILE")]
    pub token_file: Option<PathBuf>,
    /// Send the token over plain http:// to a server on another machine, where anyone on the
    /// network path can read it [default: refused; http:// to localhost or a loopback
    /// address is always allowed].
    #[arg(long)]
    pub allow_plaintext_token: bool,
}

impl DialArgs {
    /// The token of `--token-file` or `CALIB_TOKEN`, if any.
    pub fn token(&self) -> Result<Option<Token>, Failure> {
        Token::configured(self.token_file.as_deref())
            .map_err(|e| Failure::input(format!("--token-file {e}")))
    }

    pub fn client(&self) -> Result<ClientSecurity, Failure> {
        let ca = match &self.tls_ca {
            Some(path) => {
                Some(TrustedCa::load(path).map_err(|e| Failure::input(format!("--tls-ca {e}")))?)
            }
            None => None,
        };
        Ok(ClientSecurity {
            ca,
            token: self.token()?,
            allow_plaintext_token: self.allow_plaintext_token,
        })
    }
}

impl ServeArgs {
    /// A server's security: these files and the token of `dial`.
    pub fn server(&self, dial: &DialArgs) -> Result<ServerSecurity, Failure> {
        ServerSecurity::load(
            self.tls_cert.as_deref(),
            self.tls_key.as_deref(),
            dial.token()?,
        )
        .map_err(|e| Failure::input(format!("--tls-cert/--tls-key {e}")))
    }
}
