//! `starc link certs`: a private CA and the two certificates the link's mutual TLS needs, one for
//! the robot (it listens: its certificate names the addresses the rig dials) and one for the
//! rig. Pure Rust (rcgen on ring), ECDSA P-256. Keys are written 0600.

use std::io::Write;
use std::path::{Path, PathBuf};

use rcgen::{
    BasicConstraints, CertificateParams, DnType, ExtendedKeyUsagePurpose, IsCa, Issuer, KeyPair, KeyUsagePurpose,
};

use crate::LinkError;

/// The file names `make_certs` writes, relative to its output folder; config/robot.toml and
/// config/fpv.toml point at them under `config/certs/`.
pub const CA_CERT: &str = "ca.pem";
pub const CA_KEY: &str = "ca.key";
pub const ROBOT_CERT: &str = "robot.pem";
pub const ROBOT_KEY: &str = "robot.key";
pub const RIG_CERT: &str = "rig.pem";
pub const RIG_KEY: &str = "rig.key";

/// Common names, for a zenoh `access_control` policy by `cert_common_names`.
pub const ROBOT_CN: &str = "starc-robot";
pub const RIG_CN: &str = "starc-rig";

/// The addresses the shipped rig config dials (config/fpv.toml) and loopback.
pub const DEFAULT_ROBOT_HOSTS: [&str; 3] = ["192.168.50.2", "127.0.0.1", "localhost"];

/// What was written.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct CertFiles {
    pub ca_cert: PathBuf,
    pub ca_key: PathBuf,
    pub robot_cert: PathBuf,
    pub robot_key: PathBuf,
    pub rig_cert: PathBuf,
    pub rig_key: PathBuf,
}

fn certs_err(context: &'static str, e: impl std::fmt::Display) -> LinkError {
    LinkError::Certs { context, reason: e.to_string() }
}

fn leaf_params(cn: &str, names: &[String]) -> Result<CertificateParams, LinkError> {
    let mut p = CertificateParams::new(names.to_vec()).map_err(|e| certs_err("a certificate name", e))?;
    p.distinguished_name.push(DnType::CommonName, cn);
    p.is_ca = IsCa::ExplicitNoCa;
    p.key_usages = vec![KeyUsagePurpose::DigitalSignature];
    // Both ends use one certificate to listen and to connect (zenoh peers may do either).
    p.extended_key_usages = vec![ExtendedKeyUsagePurpose::ServerAuth, ExtendedKeyUsagePurpose::ClientAuth];
    p.use_authority_key_identifier_extension = true;
    Ok(p)
}

/// Writes `contents` to `path`, refusing to replace a file unless `force`; `mode` at creation
/// (keys 0600: set before any byte is written, never widened afterwards).
fn write_file(path: &Path, contents: &str, mode: u32, force: bool) -> Result<(), LinkError> {
    use std::os::unix::fs::{OpenOptionsExt, PermissionsExt};
    let io = |e: std::io::Error| LinkError::File { path: path.to_path_buf(), reason: e.to_string() };
    let mut opts = std::fs::OpenOptions::new();
    opts.write(true).mode(mode);
    if force {
        opts.create(true).truncate(true);
    } else {
        opts.create_new(true);
    }
    let mut f = opts.open(path).map_err(io)?;
    // An existing file replaced with `force` keeps its old mode through open: set it.
    f.set_permissions(std::fs::Permissions::from_mode(mode)).map_err(io)?;
    f.write_all(contents.as_bytes()).map_err(io)?;
    f.sync_all().map_err(io)
}

/// Makes a CA and the robot's and rig's certificates and keys in `out` (created 0700 if
/// missing). `robot_hosts`: every IP or DNS name the rig may dial the robot at (the rig checks
/// the name, `verify_name`). Existing files are an error unless `force`. No expiry (rcgen's
/// 1975-4096): a robot without a real-time clock may boot in 1970 or 2000, and an expired link
/// in the field is worse than a CA that must be replaced by hand; replace all six files to
/// revoke.
pub fn make_certs(out: &Path, robot_hosts: &[String], force: bool) -> Result<CertFiles, LinkError> {
    if robot_hosts.is_empty() {
        return Err(certs_err("robot hosts", "name at least one address the rig dials"));
    }
    if !out.exists() {
        use std::os::unix::fs::DirBuilderExt;
        std::fs::DirBuilder::new()
            .recursive(true)
            .mode(0o700)
            .create(out)
            .map_err(|e| LinkError::File { path: out.to_path_buf(), reason: e.to_string() })?;
    }
    let ca_key = KeyPair::generate().map_err(|e| certs_err("CA key", e))?;
    let mut ca = CertificateParams::default();
    ca.distinguished_name = rcgen::DistinguishedName::new();
    ca.distinguished_name.push(DnType::CommonName, "starc link CA");
    // Signs the two leaves only: no intermediate below it.
    ca.is_ca = IsCa::Ca(BasicConstraints::Constrained(0));
    ca.key_usages = vec![KeyUsagePurpose::KeyCertSign, KeyUsagePurpose::CrlSign];
    let ca_cert = ca.self_signed(&ca_key).map_err(|e| certs_err("CA certificate", e))?;
    let ca_key_pem = ca_key.serialize_pem();
    let issuer = Issuer::new(ca, ca_key);

    let leaf = |cn: &str, names: &[String]| -> Result<(String, String), LinkError> {
        let key = KeyPair::generate().map_err(|e| certs_err("leaf key", e))?;
        let cert = leaf_params(cn, names)?.signed_by(&key, &issuer).map_err(|e| certs_err("leaf certificate", e))?;
        Ok((cert.pem(), key.serialize_pem()))
    };
    let (robot_pem, robot_key) = leaf(ROBOT_CN, robot_hosts)?;
    let (rig_pem, rig_key) = leaf(RIG_CN, &[RIG_CN.to_string()])?;

    let files = CertFiles {
        ca_cert: out.join(CA_CERT),
        ca_key: out.join(CA_KEY),
        robot_cert: out.join(ROBOT_CERT),
        robot_key: out.join(ROBOT_KEY),
        rig_cert: out.join(RIG_CERT),
        rig_key: out.join(RIG_KEY),
    };
    if !force {
        // All or nothing: never leave a new CA beside old leaves.
        for p in [&files.ca_cert, &files.ca_key, &files.robot_cert, &files.robot_key, &files.rig_cert, &files.rig_key] {
            if p.exists() {
                return Err(LinkError::File { path: p.clone(), reason: "exists (--force replaces it)".into() });
            }
        }
    }
    write_file(&files.ca_key, &ca_key_pem, 0o600, force)?;
    write_file(&files.robot_key, &robot_key, 0o600, force)?;
    write_file(&files.rig_key, &rig_key, 0o600, force)?;
    write_file(&files.ca_cert, &ca_cert.pem(), 0o644, force)?;
    write_file(&files.robot_cert, &robot_pem, 0o644, force)?;
    write_file(&files.rig_cert, &rig_pem, 0o644, force)?;
    Ok(files)
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use std::os::unix::fs::PermissionsExt;

    #[test]
    fn keys_are_private_and_files_are_never_replaced_silently() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("certs");
        let files = make_certs(&out, &["127.0.0.1".into()], false).unwrap();
        for key in [&files.ca_key, &files.robot_key, &files.rig_key] {
            let mode = std::fs::metadata(key).unwrap().permissions().mode() & 0o777;
            assert_eq!(mode, 0o600, "{}", key.display());
            assert!(std::fs::read_to_string(key).unwrap().starts_with("-----BEGIN PRIVATE KEY-----"));
        }
        assert_eq!(std::fs::metadata(&out).unwrap().permissions().mode() & 0o777, 0o700);
        assert!(std::fs::read_to_string(&files.robot_cert).unwrap().starts_with("-----BEGIN CERTIFICATE-----"));
        let before = std::fs::read(&files.ca_cert).unwrap();
        let e = make_certs(&out, &["127.0.0.1".into()], false).unwrap_err();
        assert!(e.to_string().contains("ca.pem") || e.to_string().contains(".key"), "{e}");
        assert_eq!(std::fs::read(&files.ca_cert).unwrap(), before);
        make_certs(&out, &["127.0.0.1".into()], true).unwrap();
        assert_ne!(std::fs::read(&files.ca_cert).unwrap(), before);
        assert!(make_certs(&out, &[], true).is_err());
    }
}
