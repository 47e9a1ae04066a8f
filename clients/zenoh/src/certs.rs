//! `chassis-zenoh gen-certs DIR --host ADDR…`: a certificate authority of its own, and one
//! certificate for each side signed by it — the robot's (its addresses as subject alternative
//! names, checked by the operator when it connects) and the operator's (the common name the
//! robot's access list names). Each side needs `ca.pem` and its own certificate and key; the
//! CA's key stays with whoever issues certificates.

use std::fs;
use std::io::Write as _;
use std::os::unix::fs::OpenOptionsExt as _;
use std::path::Path;

use anyhow::Context as _;
use rcgen::{
    BasicConstraints, CertificateParams, CertifiedIssuer, DnType, ExtendedKeyUsagePurpose, IsCa,
    KeyPair, KeyUsagePurpose,
};

use crate::net::{
    CA_CERT, OPERATOR_CERT, OPERATOR_CN, OPERATOR_KEY, ROBOT_CERT, ROBOT_CN, ROBOT_KEY,
};

/// The CA's private key (not needed by either side once the certificates are made).
pub const CA_KEY: &str = "ca-key.pem";

fn write(dir: &Path, file: &str, text: &str, secret: bool) -> anyhow::Result<()> {
    let path = dir.join(file);
    let mut options = fs::OpenOptions::new();
    options.write(true).create(true).truncate(true);
    if secret {
        options.mode(0o600);
    }
    options
        .open(&path)
        .and_then(|mut f| f.write_all(text.as_bytes()))
        .with_context(|| format!("writing {}", path.display()))
}

fn leaf(
    cn: &str,
    names: Vec<String>,
    issuer: &CertifiedIssuer<'_, KeyPair>,
) -> anyhow::Result<(String, String)> {
    let key = KeyPair::generate()?;
    let mut params = CertificateParams::new(names)?;
    params.distinguished_name.push(DnType::CommonName, cn);
    params.key_usages = vec![
        KeyUsagePurpose::DigitalSignature,
        KeyUsagePurpose::KeyEncipherment,
    ];
    params.extended_key_usages = vec![
        ExtendedKeyUsagePurpose::ServerAuth,
        ExtendedKeyUsagePurpose::ClientAuth,
    ];
    let cert = params.signed_by(&key, issuer)?;
    Ok((cert.pem(), key.serialize_pem()))
}

/// Writes the CA, the robot's and the operator's certificates and keys into `dir`. `hosts` are
/// the robot's addresses or DNS names the operator connects to.
pub fn generate(dir: &Path, hosts: &[String]) -> anyhow::Result<()> {
    fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let ca_key = KeyPair::generate()?;
    let mut ca = CertificateParams::new(Vec::<String>::new())?;
    ca.is_ca = IsCa::Ca(BasicConstraints::Unconstrained);
    ca.distinguished_name
        .push(DnType::CommonName, "chassis-zenoh CA");
    ca.key_usages = vec![
        KeyUsagePurpose::KeyCertSign,
        KeyUsagePurpose::CrlSign,
        KeyUsagePurpose::DigitalSignature,
    ];
    let ca_key_pem = ca_key.serialize_pem();
    let issuer = CertifiedIssuer::self_signed(ca, ca_key)?;
    write(dir, CA_CERT, &issuer.pem(), false)?;
    write(dir, CA_KEY, &ca_key_pem, true)?;

    let mut robot_names = hosts.to_vec();
    if robot_names.is_empty() {
        robot_names = vec!["localhost".into(), "127.0.0.1".into()];
    }
    let (cert, key) = leaf(ROBOT_CN, robot_names, &issuer)?;
    write(dir, ROBOT_CERT, &cert, false)?;
    write(dir, ROBOT_KEY, &key, true)?;
    let (cert, key) = leaf(OPERATOR_CN, vec![OPERATOR_CN.into()], &issuer)?;
    write(dir, OPERATOR_CERT, &cert, false)?;
    write(dir, OPERATOR_KEY, &key, true)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_file_is_written_and_the_keys_are_private() {
        let dir = std::env::temp_dir().join(format!("chassis-zenoh-certs-{}", std::process::id()));
        generate(&dir, &["10.77.0.1".into(), "titan.local".into()]).unwrap();
        for file in [
            CA_CERT,
            CA_KEY,
            ROBOT_CERT,
            ROBOT_KEY,
            OPERATOR_CERT,
            OPERATOR_KEY,
        ] {
            let text = fs::read_to_string(dir.join(file)).unwrap();
            assert!(text.starts_with("-----BEGIN "), "{file}: {text}");
        }
        use std::os::unix::fs::PermissionsExt as _;
        let mode = fs::metadata(dir.join(ROBOT_KEY))
            .unwrap()
            .permissions()
            .mode();
        assert_eq!(mode & 0o077, 0, "{mode:o}");
        fs::remove_dir_all(&dir).unwrap();
    }
}
