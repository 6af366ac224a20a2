//! A client's security: the CA it trusts for `https://` servers and the token it presents.

use crate::error::SecurityError;
use crate::tls::{chain, TrustedCa};
use crate::token::Token;
use tonic::metadata::{Ascii, MetadataValue};
use tonic::service::interceptor::InterceptedService;
use tonic::transport::{Channel, ClientTlsConfig, Endpoint};

/// How a client dials servers. The default trusts the system's root certificates for
/// `https://` and presents no token.
#[derive(Debug, Clone, Default)]
pub struct ClientSecurity {
    /// CA to trust for `https://` servers instead of the system's roots.
    pub ca: Option<TrustedCa>,
    pub token: Option<Token>,
}

/// A channel that presents the token on every request.
pub type SecureChannel = InterceptedService<Channel, PresentToken>;

impl ClientSecurity {
    /// An endpoint for `url`: TLS for `https://` (verifying the server as `server_name`,
    /// by default the URL's host), plain HTTP/2 for `http://`.
    pub fn endpoint(
        &self,
        url: &str,
        server_name: Option<&str>,
    ) -> Result<Endpoint, SecurityError> {
        let url_error = |reason: String| SecurityError::Url {
            url: url.to_string(),
            reason,
        };
        let endpoint = Endpoint::from_shared(url.to_string()).map_err(|e| url_error(chain(&e)))?;
        if !url.starts_with("https://") {
            return Ok(endpoint);
        }
        let mut tls = ClientTlsConfig::new();
        tls = match &self.ca {
            Some(ca) => tls.ca_certificate(ca.certificate().clone()),
            None => tls.with_native_roots(),
        };
        if let Some(name) = server_name {
            tls = tls.domain_name(name);
        }
        endpoint.tls_config(tls).map_err(|e| {
            url_error(match self.ca {
                Some(_) => chain(&e),
                None => format!(
                    "no CA to trust among the system's root certificates ({}); give the CA \
                     that signed the server's certificate with --tls-ca FILE",
                    chain(&e)
                ),
            })
        })
    }

    /// `channel`, presenting the token (when there is one) on every request.
    pub fn authorize(&self, channel: Channel) -> SecureChannel {
        InterceptedService::new(channel, PresentToken::new(self.token.as_ref()))
    }
}

/// Adds `authorization: Bearer <token>` to every request.
#[derive(Clone)]
pub struct PresentToken {
    value: Option<MetadataValue<Ascii>>,
}

impl PresentToken {
    pub fn new(token: Option<&Token>) -> Self {
        Self {
            value: token.map(|t| {
                let mut value: MetadataValue<Ascii> =
                    t.header_value().parse().expect("a token is visible ASCII");
                value.set_sensitive(true);
                value
            }),
        }
    }
}

impl std::fmt::Debug for PresentToken {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("PresentToken")
            .field("token", &self.value.as_ref().map(|_| "<redacted>"))
            .finish()
    }
}

impl tonic::service::Interceptor for PresentToken {
    fn call(
        &mut self,
        mut request: tonic::Request<()>,
    ) -> Result<tonic::Request<()>, tonic::Status> {
        if let Some(value) = &self.value {
            request
                .metadata_mut()
                .insert("authorization", value.clone());
        }
        Ok(request)
    }
}
