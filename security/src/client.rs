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
    /// Send the token over plain `http://` to a server on another machine, where anyone on
    /// the way can read it (`--allow-plaintext-token`). Without it such a URL is refused.
    pub allow_plaintext_token: bool,
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
            if self.token.is_some() && !self.allow_plaintext_token && !is_loopback(endpoint.uri()) {
                return Err(url_error(
                    "the token would travel in clear text over plain http to another                      machine; dial https:// (the server serving TLS with --tls-cert), or                      pass --allow-plaintext-token on a network you trust"
                        .into(),
                ));
            }
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

/// True when `uri` names this machine: `localhost` or a loopback address.
fn is_loopback(uri: &http::Uri) -> bool {
    let Some(host) = uri.host() else {
        return false;
    };
    let host = host.trim_start_matches('[').trim_end_matches(']');
    host.eq_ignore_ascii_case("localhost")
        || host
            .parse::<std::net::IpAddr>()
            .is_ok_and(|ip| ip.is_loopback())
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

#[cfg(test)]
mod tests {
    use super::*;

    fn with_token(allow_plaintext_token: bool) -> ClientSecurity {
        ClientSecurity {
            ca: None,
            token: Some(Token::new("a-token-of-32-characters-or-more!").unwrap()),
            allow_plaintext_token,
        }
    }

    #[test]
    fn a_token_is_not_sent_over_plain_http_to_another_machine_unless_allowed() {
        for url in [
            "http://10.0.0.5:50050",
            "http://calib-coordinator:50050",
            "http://[2001:db8::1]:50051",
            "http://localhost.example:1",
        ] {
            let error = with_token(false)
                .endpoint(url, None)
                .unwrap_err()
                .to_string();
            assert!(
                error.starts_with(url) && error.contains("--allow-plaintext-token"),
                "{error}"
            );
            assert!(with_token(true).endpoint(url, None).is_ok(), "{url}");
            let tokenless = ClientSecurity::default();
            assert!(tokenless.endpoint(url, None).is_ok(), "{url}");
        }
        for url in [
            "http://127.0.0.1:50050",
            "http://127.3.2.1:50050",
            "http://localhost:50050",
            "http://LOCALHOST:1",
            "http://[::1]:50051",
            "https://10.0.0.5:50050",
        ] {
            assert!(with_token(false).endpoint(url, None).is_ok(), "{url}");
        }
    }
}
