//! A failed call in words: a certificate the client does not trust, a token the server
//! refused. Neither gets better by asking again.

use std::error::Error;

/// Why a call failed for want of trust, or `None` when it failed otherwise.
pub fn refusal(status: &tonic::Status) -> Option<String> {
    if status.code() == tonic::Code::Unauthenticated {
        return Some(format!(
            "the token was refused (UNAUTHENTICATED: {}); give the cluster's token with \
             --token-file FILE or {}",
            status.message(),
            crate::token::TOKEN_ENV
        ));
    }
    tls_failure(status).map(|reason| {
        format!(
            "TLS handshake failed: {reason}; check that --tls-ca names the CA that signed the \
             server's certificate and that the certificate is made out to the name dialed"
        )
    })
}

/// The TLS error among the sources of `error`, in words.
pub fn tls_failure(error: &(dyn Error + 'static)) -> Option<String> {
    let mut next: Option<&(dyn Error + 'static)> = Some(error);
    while let Some(e) = next {
        if let Some(tls) = e.downcast_ref::<rustls::Error>() {
            return Some(tls.to_string());
        }
        // An I/O error hides the error it wraps from `source()`.
        if let Some(io) = e.downcast_ref::<std::io::Error>() {
            if let Some(tls) = io.get_ref().and_then(|i| i.downcast_ref::<rustls::Error>()) {
                return Some(tls.to_string());
            }
        }
        next = e.source();
    }
    None
}
