//! Certificates and keys from PEM files, checked when loaded so that a bad file is named
//! at startup rather than found at the first connection.

use crate::error::SecurityError;
use rustls_pki_types::pem::PemObject;
use rustls_pki_types::{CertificateDer, PrivateKeyDer};
use std::path::{Path, PathBuf};
use tonic::transport::{Certificate, Identity, ServerTlsConfig};

/// A server's certificate chain and private key.
#[derive(Clone)]
pub struct ServerTls {
    cert: PathBuf,
    key: PathBuf,
    identity: Identity,
}

impl ServerTls {
    /// Read the certificate chain of `cert` and the private key of `key` (PEM), and check
    /// that TLS can serve with them.
    pub fn load(cert: &Path, key: &Path) -> Result<Self, SecurityError> {
        let cert_pem = read(cert)?;
        let key_pem = read(key)?;
        let certs = CertificateDer::pem_slice_iter(&cert_pem)
            .collect::<Result<Vec<_>, _>>()
            .map_err(|e| file_error(cert, format!("not a PEM certificate: {e}")))?;
        if certs.is_empty() {
            return Err(file_error(cert, "no PEM certificate in it".into()));
        }
        PrivateKeyDer::from_pem_slice(&key_pem)
            .map_err(|e| file_error(key, format!("no PEM private key in it: {e}")))?;
        let identity = Identity::from_pem(cert_pem, key_pem);
        tonic::transport::Server::builder()
            .tls_config(ServerTlsConfig::new().identity(identity.clone()))
            .map_err(|e| SecurityError::Pair {
                cert: cert.to_path_buf(),
                key: key.to_path_buf(),
                reason: format!("not a usable certificate and key: {}", chain(&e)),
            })?;
        Ok(Self {
            cert: cert.to_path_buf(),
            key: key.to_path_buf(),
            identity,
        })
    }

    pub fn cert(&self) -> &Path {
        &self.cert
    }

    pub fn key(&self) -> &Path {
        &self.key
    }

    pub fn config(&self) -> ServerTlsConfig {
        ServerTlsConfig::new().identity(self.identity.clone())
    }
}

/// Shows the files, never the key.
impl std::fmt::Debug for ServerTls {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ServerTls")
            .field("cert", &self.cert)
            .field("key", &self.key)
            .finish_non_exhaustive()
    }
}

/// Certificate authorities a client trusts, from one PEM file.
#[derive(Clone)]
pub struct TrustedCa {
    path: PathBuf,
    certificate: Certificate,
}

impl TrustedCa {
    /// Read the CA certificates of `path` (PEM).
    pub fn load(path: &Path) -> Result<Self, SecurityError> {
        let pem = read(path)?;
        let certs = CertificateDer::pem_slice_iter(&pem)
            .collect::<Result<Vec<_>, _>>()
            .map_err(|e| file_error(path, format!("not a PEM certificate: {e}")))?;
        if certs.is_empty() {
            return Err(file_error(path, "no PEM certificate in it".into()));
        }
        Ok(Self {
            path: path.to_path_buf(),
            certificate: Certificate::from_pem(pem),
        })
    }

    pub fn certificate(&self) -> &Certificate {
        &self.certificate
    }
}

impl std::fmt::Debug for TrustedCa {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("TrustedCa")
            .field("path", &self.path)
            .finish_non_exhaustive()
    }
}

fn read(path: &Path) -> Result<Vec<u8>, SecurityError> {
    std::fs::read(path).map_err(|e| file_error(path, e.to_string()))
}

fn file_error(path: &Path, reason: String) -> SecurityError {
    SecurityError::File {
        path: path.to_path_buf(),
        reason,
    }
}

/// An error and its sources, in one line.
pub(crate) fn chain(error: &(dyn std::error::Error + 'static)) -> String {
    let mut text = error.to_string();
    let mut source = error.source();
    while let Some(e) = source {
        let next = e.to_string();
        if !text.contains(&next) {
            text.push_str(": ");
            text.push_str(&next);
        }
        source = e.source();
    }
    text
}
