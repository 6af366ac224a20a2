//! The server side of the bearer token: a tower layer in front of every service that
//! answers `UNAUTHENTICATED` to a request without the token or with another one.
//!
//! Health checks (`grpc.health.v1.Health`) stay open, so that probes and load balancers
//! need no secret; they tell nothing but whether the server serves. Every other service,
//! reflection included, requires the token.

use crate::token::Token;
use std::future::Future;
use std::pin::Pin;
use std::task::{Context, Poll};

/// Path prefix of the gRPC health service, open without a token.
const HEALTH: &str = "/grpc.health.v1.Health/";

/// Requires the token when there is one; lets everything through otherwise.
#[derive(Debug, Clone, Default)]
pub struct RequireTokenLayer {
    token: Option<Token>,
}

impl RequireTokenLayer {
    pub fn new(token: Option<Token>) -> Self {
        Self { token }
    }
}

impl<S> tower_layer::Layer<S> for RequireTokenLayer {
    type Service = RequireToken<S>;

    fn layer(&self, inner: S) -> Self::Service {
        RequireToken {
            inner,
            token: self.token.clone(),
        }
    }
}

#[derive(Debug, Clone)]
pub struct RequireToken<S> {
    inner: S,
    token: Option<Token>,
}

impl<S> RequireToken<S> {
    /// Why `request` is refused, or `None` when it may pass.
    fn refusal<B>(&self, request: &http::Request<B>) -> Option<tonic::Status> {
        let token = self.token.as_ref()?;
        if request.uri().path().starts_with(HEALTH) {
            return None;
        }
        let Some(value) = request.headers().get(http::header::AUTHORIZATION) else {
            return Some(tonic::Status::unauthenticated(
                "a bearer token is required (authorization: Bearer …)",
            ));
        };
        if token.matches(crate::token::bearer(value.as_bytes())) {
            None
        } else {
            Some(tonic::Status::unauthenticated(
                "the bearer token is not valid",
            ))
        }
    }
}

impl<S, B, ResBody> tower_service::Service<http::Request<B>> for RequireToken<S>
where
    S: tower_service::Service<http::Request<B>, Response = http::Response<ResBody>>,
    S::Future: Send + 'static,
    S::Error: Send + 'static,
    ResBody: Default + Send + 'static,
{
    type Response = S::Response;
    type Error = S::Error;
    type Future = Pin<Box<dyn Future<Output = Result<S::Response, S::Error>> + Send>>;

    fn poll_ready(&mut self, cx: &mut Context<'_>) -> Poll<Result<(), Self::Error>> {
        self.inner.poll_ready(cx)
    }

    fn call(&mut self, request: http::Request<B>) -> Self::Future {
        match self.refusal(&request) {
            Some(status) => Box::pin(std::future::ready(Ok(status.into_http()))),
            None => Box::pin(self.inner.call(request)),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn request(path: &str, authorization: Option<&str>) -> http::Request<()> {
        let mut builder = http::Request::builder().uri(format!("http://w{path}"));
        if let Some(value) = authorization {
            builder = builder.header("authorization", value);
        }
        builder.body(()).unwrap()
    }

    fn layer(token: Option<&str>) -> RequireToken<()> {
        RequireToken {
            inner: (),
            token: token.map(|t| Token::new(t).unwrap()),
        }
    }

    #[test]
    fn refuses_a_missing_or_wrong_token_but_not_health_checks() {
        let guarded = layer(Some("right"));
        let simulate = "/calib.v1.Simulator/Simulate";
        assert!(guarded
            .refusal(&request(simulate, Some("Bearer right")))
            .is_none());
        for presented in [
            None,
            Some("Bearer wrong"),
            Some("Bearer "),
            Some("Basic right"),
        ] {
            let status = guarded
                .refusal(&request(simulate, presented))
                .unwrap_or_else(|| panic!("{presented:?} let through"));
            assert_eq!(status.code(), tonic::Code::Unauthenticated);
        }
        assert!(guarded
            .refusal(&request("/grpc.health.v1.Health/Check", None))
            .is_none());
        assert!(layer(None).refusal(&request(simulate, None)).is_none());
    }
}
