//! The bearer token shared by a cluster: read from a file or the environment, compared in
//! constant time, never printed.

use crate::error::SecurityError;
use std::path::Path;
use std::sync::Arc;

/// The environment variable that holds the token when no token file is given.
pub const TOKEN_ENV: &str = "CALIB_TOKEN";

/// A shared secret that servers require and clients present as `authorization: Bearer …`.
/// Its `Debug` shows no part of it.
#[derive(Clone, PartialEq, Eq)]
pub struct Token(Arc<str>);

impl Token {
    /// A token of visible ASCII characters (it travels in an HTTP header), surrounding
    /// whitespace removed.
    pub fn new(text: &str) -> Result<Self, String> {
        let text = text.trim();
        if text.is_empty() {
            return Err("the token is empty".into());
        }
        if !text.bytes().all(|b| b.is_ascii_graphic()) {
            return Err("the token must be visible ASCII characters without spaces".into());
        }
        Ok(Self(text.into()))
    }

    /// The token in `path` (its only line; a trailing newline is ignored).
    pub fn from_file(path: &Path) -> Result<Self, SecurityError> {
        let text = std::fs::read_to_string(path).map_err(|e| SecurityError::File {
            path: path.to_path_buf(),
            reason: e.to_string(),
        })?;
        Self::new(&text).map_err(|reason| SecurityError::File {
            path: path.to_path_buf(),
            reason,
        })
    }

    /// The token of `file` when given, else of [`TOKEN_ENV`] when set, else none.
    pub fn configured(file: Option<&Path>) -> Result<Option<Self>, SecurityError> {
        if let Some(path) = file {
            return Self::from_file(path).map(Some);
        }
        match std::env::var(TOKEN_ENV) {
            Ok(text) => Self::new(&text)
                .map(Some)
                .map_err(|reason| SecurityError::Environment {
                    variable: TOKEN_ENV,
                    reason,
                }),
            Err(std::env::VarError::NotPresent) => Ok(None),
            Err(e) => Err(SecurityError::Environment {
                variable: TOKEN_ENV,
                reason: e.to_string(),
            }),
        }
    }

    /// True when `presented` is this token. Every byte is compared whatever the first
    /// difference, so the time taken tells nothing of how much of a guess was right.
    pub fn matches(&self, presented: &[u8]) -> bool {
        let expected = self.0.as_bytes();
        if presented.len() != expected.len() {
            return false;
        }
        let difference = expected
            .iter()
            .zip(presented)
            .fold(0u8, |acc, (a, b)| acc | (a ^ b));
        std::hint::black_box(difference) == 0
    }

    /// The value of the `authorization` header that presents this token.
    pub(crate) fn header_value(&self) -> String {
        format!("Bearer {}", self.0)
    }
}

impl std::fmt::Debug for Token {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("Token(<redacted>)")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn matches_only_itself() {
        let token = Token::new("s3cret-token\n").unwrap();
        assert!(token.matches(b"s3cret-token"));
        for other in [&b"s3cret-tokem"[..], b"s3cret-toke", b"s3cret-token!", b""] {
            assert!(!token.matches(other), "{other:?}");
        }
    }

    #[test]
    fn debug_shows_no_part_of_it() {
        let token = Token::new("s3cret-token").unwrap();
        let shown = format!("{token:?} {:?}", Some(token.clone()));
        assert!(!shown.contains("s3cret"), "{shown}");
        assert!(shown.contains("redacted"), "{shown}");
    }

    #[test]
    fn refuses_what_cannot_travel_in_a_header() {
        for bad in ["", "  \n", "two words", "tab\there", "ünïcode"] {
            assert!(Token::new(bad).is_err(), "{bad:?}");
        }
    }

    #[test]
    fn a_missing_token_file_is_named() {
        let error = Token::from_file(Path::new("/nonexistent/token")).unwrap_err();
        assert!(error.to_string().contains("/nonexistent/token"), "{error}");
    }
}
