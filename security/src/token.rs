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

    /// The token of `file` when given, else of [`TOKEN_ENV`] when set, else none. Each of
    /// [`weaknesses`] is logged as a warning.
    pub fn configured(file: Option<&Path>) -> Result<Option<Self>, SecurityError> {
        let token = Self::configured_quietly(file)?;
        if let Some(token) = &token {
            // A server reads the token for its own door and again to dial: each warning
            // is said once per process.
            static SAID: std::sync::Mutex<Vec<String>> = std::sync::Mutex::new(Vec::new());
            let mut said = SAID.lock().unwrap_or_else(|e| e.into_inner());
            for weakness in weaknesses(token, file) {
                if !said.contains(&weakness) {
                    tracing::warn!("{weakness}");
                    said.push(weakness);
                }
            }
        }
        Ok(token)
    }

    fn configured_quietly(file: Option<&Path>) -> Result<Option<Self>, SecurityError> {
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

/// Shortest token not warned about: 16 bytes, 128 bits when drawn from random bytes and
/// written in hex or base64 (`openssl rand -hex 16`).
pub const MIN_TOKEN_BYTES: usize = 16;

/// What makes `token` (read from `file`, when it came from one) easy to steal or guess, in
/// words with what to do: a file others may read, a token shorter than [`MIN_TOKEN_BYTES`].
pub fn weaknesses(token: &Token, file: Option<&Path>) -> Vec<String> {
    let mut found = Vec::new();
    let source = match file {
        Some(path) => format!("the token in {}", path.display()),
        None => format!("the token of {TOKEN_ENV}"),
    };
    if token.0.len() < MIN_TOKEN_BYTES {
        found.push(format!(
            "{source} is {} bytes, shorter than {MIN_TOKEN_BYTES}: it can be guessed; make \
             one with `openssl rand -hex 32`",
            token.0.len()
        ));
    }
    #[cfg(unix)]
    if let Some(path) = file {
        use std::os::unix::fs::PermissionsExt;
        if let Ok(meta) = std::fs::metadata(path) {
            let mode = meta.permissions().mode();
            if mode & 0o077 != 0 {
                found.push(format!(
                    "{} can be read by other users (mode {:o}); `chmod 600 {}`",
                    path.display(),
                    mode & 0o777,
                    path.display()
                ));
            }
        }
    }
    found
}

/// The token an `authorization` header's value presents: what follows `Bearer ` (or
/// `bearer `), or the whole value.
pub fn bearer(value: &[u8]) -> &[u8] {
    value
        .strip_prefix(b"Bearer ")
        .or_else(|| value.strip_prefix(b"bearer "))
        .unwrap_or(value)
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
    fn a_short_token_or_a_file_others_can_read_is_a_weakness() {
        use std::os::unix::fs::PermissionsExt;
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("token");
        let strong = "0123456789abcdef";
        std::fs::write(&path, format!("{strong}\n")).unwrap();
        std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o600)).unwrap();
        let token = Token::from_file(&path).unwrap();
        assert_eq!(weaknesses(&token, Some(&path)), Vec::<String>::new());

        std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o640)).unwrap();
        let found = weaknesses(&token, Some(&path));
        assert_eq!(found.len(), 1, "{found:?}");
        assert!(
            found[0].contains("read by other users") && found[0].contains("chmod 600"),
            "{found:?}"
        );

        std::fs::write(&path, "x").unwrap();
        std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o604)).unwrap();
        let short = Token::from_file(&path).unwrap();
        let found = weaknesses(&short, Some(&path));
        assert_eq!(found.len(), 2, "{found:?}");
        assert!(found[0].contains("1 bytes, shorter than 16"), "{found:?}");
        let found = weaknesses(&short, None);
        assert!(
            found.len() == 1 && found[0].starts_with("the token of CALIB_TOKEN"),
            "{found:?}"
        );
    }

    #[test]
    fn a_missing_token_file_is_named() {
        let error = Token::from_file(Path::new("/nonexistent/token")).unwrap_err();
        assert!(error.to_string().contains("/nonexistent/token"), "{error}");
    }
}
