//! A server's security: TLS when it has a certificate, the token when it has one.

use crate::auth::RequireTokenLayer;
use crate::error::SecurityError;
use crate::tls::ServerTls;
use crate::token::Token;
use std::path::Path;
use tonic::transport::Server;
use tower_layer::{Identity, Stack};

/// How a server secures its connections and requests. The default serves plain HTTP/2 to
/// anyone, as a server on a trusted network.
#[derive(Debug, Clone, Default)]
pub struct ServerSecurity {
    pub tls: Option<ServerTls>,
    pub token: Option<Token>,
}

/// A server builder with the token check in front of every service.
pub type SecureServer = Server<Stack<RequireTokenLayer, Identity>>;

impl ServerSecurity {
    /// From the command line: a certificate and key (both or neither) and the token.
    pub fn load(
        cert: Option<&Path>,
        key: Option<&Path>,
        token: Option<Token>,
    ) -> Result<Self, SecurityError> {
        let tls = match (cert, key) {
            (Some(cert), Some(key)) => Some(ServerTls::load(cert, key)?),
            (None, None) => None,
            (Some(cert), None) => {
                return Err(SecurityError::File {
                    path: cert.to_path_buf(),
                    reason: "a certificate needs its private key (--tls-key)".into(),
                })
            }
            (None, Some(key)) => {
                return Err(SecurityError::File {
                    path: key.to_path_buf(),
                    reason: "a private key needs its certificate (--tls-cert)".into(),
                })
            }
        };
        Ok(Self { tls, token })
    }

    /// `http` or `https`, as clients dial this server.
    pub fn scheme(&self) -> &'static str {
        if self.tls.is_some() {
            "https"
        } else {
            "http"
        }
    }

    /// `builder` serving TLS when configured, with the token required in front of every
    /// service but health checks.
    pub fn apply(&self, builder: Server) -> Result<SecureServer, SecurityError> {
        let builder = match &self.tls {
            Some(tls) => builder
                .tls_config(tls.config())
                .map_err(|e| SecurityError::Pair {
                    cert: tls.cert().to_path_buf(),
                    key: tls.key().to_path_buf(),
                    reason: crate::tls::chain(&e),
                })?,
            None => builder,
        };
        Ok(builder.layer(RequireTokenLayer::new(self.token.clone())))
    }
}
