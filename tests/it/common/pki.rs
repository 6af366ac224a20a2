//! Certificates made at test time: a CA and a server certificate it signed.

use calib_security::{ClientSecurity, ServerSecurity, ServerTls, Token, TrustedCa};
use std::path::PathBuf;

/// A CA and a server certificate it signed, made out to `localhost` and `127.0.0.1`, as
/// PEM files in a temporary folder.
pub struct Pki {
    pub dir: tempfile::TempDir,
    pub ca: PathBuf,
    pub cert: PathBuf,
    pub key: PathBuf,
}

impl Pki {
    pub fn new() -> Self {
        use rcgen::{
            BasicConstraints, CertificateParams, DnType, IsCa, Issuer, KeyPair, KeyUsagePurpose,
        };
        let dir = tempfile::tempdir().unwrap();
        let ca_key = KeyPair::generate().unwrap();
        let mut ca_params = CertificateParams::new(Vec::<String>::new()).unwrap();
        ca_params.is_ca = IsCa::Ca(BasicConstraints::Unconstrained);
        ca_params
            .distinguished_name
            .push(DnType::CommonName, "calib test CA");
        ca_params.key_usages = vec![
            KeyUsagePurpose::KeyCertSign,
            KeyUsagePurpose::CrlSign,
            KeyUsagePurpose::DigitalSignature,
        ];
        let ca_cert = ca_params.self_signed(&ca_key).unwrap();
        let issuer = Issuer::new(ca_params, ca_key);
        let key = KeyPair::generate().unwrap();
        let cert = CertificateParams::new(vec!["localhost".to_string(), "127.0.0.1".to_string()])
            .unwrap()
            .signed_by(&key, &issuer)
            .unwrap();
        let pki = Self {
            ca: dir.path().join("ca.pem"),
            cert: dir.path().join("server.pem"),
            key: dir.path().join("server.key"),
            dir,
        };
        std::fs::write(&pki.ca, ca_cert.pem()).unwrap();
        std::fs::write(&pki.cert, cert.pem()).unwrap();
        std::fs::write(&pki.key, key.serialize_pem()).unwrap();
        pki
    }

    pub fn server(&self, token: Option<&str>) -> ServerSecurity {
        ServerSecurity {
            tls: Some(ServerTls::load(&self.cert, &self.key).unwrap()),
            token: token.map(|t| Token::new(t).unwrap()),
        }
    }

    pub fn client(&self, token: Option<&str>) -> ClientSecurity {
        ClientSecurity {
            ca: Some(TrustedCa::load(&self.ca).unwrap()),
            token: token.map(|t| Token::new(t).unwrap()),
            allow_plaintext_token: false,
        }
    }

    /// `text` in a file of this folder.
    pub fn file(&self, name: &str, text: &str) -> PathBuf {
        super::write(self.dir.path(), name, text)
    }
}
