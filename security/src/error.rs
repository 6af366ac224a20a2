//! What can go wrong setting up security: each message names the file or variable at fault.

use std::path::PathBuf;

#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum SecurityError {
    /// A certificate, key or token file that cannot be read or holds no usable content.
    #[error("{}: {reason}", path.display())]
    File { path: PathBuf, reason: String },
    /// A certificate and a key that TLS cannot use together.
    #[error("{} and {}: {reason}", cert.display(), key.display())]
    Pair {
        cert: PathBuf,
        key: PathBuf,
        reason: String,
    },
    /// An environment variable that holds no usable value.
    #[error("{variable}: {reason}")]
    Environment {
        variable: &'static str,
        reason: String,
    },
    /// A client that cannot dial `url` as configured.
    #[error("{url}: {reason}")]
    Url { url: String, reason: String },
}
