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
    tls_failure(status)
}

/// The TLS error among the sources of `error`, in words with what to check.
pub fn tls_failure(error: &(dyn Error + 'static)) -> Option<String> {
    let tls = find_tls_error(error)?;
    let hint = match tls {
        rustls::Error::InvalidCertificate(_) | rustls::Error::NoCertificatesPresented => {
            "check that --tls-ca names the CA that signed the server's certificate and that \
             the certificate is made out to the name dialed"
        }
        rustls::Error::InvalidMessage(_) | rustls::Error::InappropriateMessage { .. } => {
            "is the server serving TLS? A server without --tls-cert is dialed http://"
        }
        _ => "check the server's certificate and the CA given with --tls-ca",
    };
    Some(format!("TLS handshake failed: {tls}; {hint}"))
}

fn find_tls_error<'a>(error: &'a (dyn Error + 'static)) -> Option<&'a rustls::Error> {
    let mut next: Option<&(dyn Error + 'static)> = Some(error);
    while let Some(e) = next {
        if let Some(tls) = e.downcast_ref::<rustls::Error>() {
            return Some(tls);
        }
        // An I/O error hides the error it wraps from `source()`.
        if let Some(io) = e.downcast_ref::<std::io::Error>() {
            if let Some(tls) = io.get_ref().and_then(|i| i.downcast_ref::<rustls::Error>()) {
                return Some(tls);
            }
        }
        next = e.source();
    }
    None
}

/// A hint for a call over plain HTTP/2 that the server answered with something else, as a
/// TLS server does. What the client sees depends on who is first: an HTTP/2 protocol error,
/// a cancelled call or a bare transport error when the server closes the connection. The
/// hint is worded as a condition, since the last two also have other causes; `None` for
/// any other failure.
pub fn plain_to_tls_hint(status: &tonic::Status) -> Option<&'static str> {
    let garbled =
        status.code() == tonic::Code::Internal && status.message().contains("h2 protocol error");
    let closed = status.code() == tonic::Code::Cancelled
        && status.message().contains("operation was canceled");
    let dropped = status.code() == tonic::Code::Unknown && status.message() == "transport error";
    (garbled || closed || dropped).then_some("if the server serves TLS, dial it with https://")
}

#[cfg(test)]
mod plain_to_tls_tests {
    use super::plain_to_tls_hint;
    use tonic::Status;

    #[test]
    fn each_way_a_tls_server_answers_plain_http2_gets_the_hint() {
        for status in [
            Status::internal("h2 protocol error: frame with invalid size"),
            Status::cancelled("operation was canceled: connection closed"),
            Status::unknown("transport error"),
        ] {
            assert!(plain_to_tls_hint(&status).is_some(), "{status:?}");
        }
        for status in [
            Status::unknown("something else"),
            Status::unavailable("transport error"),
            Status::invalid_argument("transport error"),
        ] {
            assert!(plain_to_tls_hint(&status).is_none(), "{status:?}");
        }
    }
}
