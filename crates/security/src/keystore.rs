//! A keystore laid out as `ros2 security create_keystore` and `create_enclave` (ros2/sros2,
//! `sros2/keystore/_keystore.py`, `_enclave.py`) lay it out, so that any ROS 2 middleware finds an
//! enclave where it looks (`$ROS_SECURITY_KEYSTORE/enclaves/<name>`):
//!
//! ```text
//! public/ca.cert.pem                 the authority's certificate
//! public/identity_ca.cert.pem        → ca.cert.pem (one authority signs identities and permissions)
//! public/permissions_ca.cert.pem     → ca.cert.pem
//! private/ca.key.pem                 its key, mode 0600
//! private/identity_ca.key.pem        → ca.key.pem
//! private/permissions_ca.key.pem     → ca.key.pem
//! enclaves/governance.xml, governance.p7s
//! enclaves/<name>/cert.pem, key.pem (0600), permissions.xml, permissions.p7s
//! enclaves/<name>/identity_ca.cert.pem, permissions_ca.cert.pem, governance.p7s  → the keystore's
//! ```
//!
//! The arrows are relative symbolic links, as sros2 makes them.

use std::fs;
use std::io::Write;
use std::os::unix::fs::{OpenOptionsExt, symlink};
use std::path::{Path, PathBuf};

use crate::Error;
use crate::pki::{AUTHORITY_NAME, Identity};
use crate::policy::{Grant, governance};
use crate::smime;

const PUBLIC: &str = "public";
const PRIVATE: &str = "private";
const ENCLAVES: &str = "enclaves";

/// Whether `dir` holds a keystore (sros2's `is_valid_keystore`: both authorities and the signed
/// governance).
pub fn is_keystore(dir: &Path) -> bool {
    [
        "public/permissions_ca.cert.pem",
        "public/identity_ca.cert.pem",
        "private/permissions_ca.key.pem",
        "private/identity_ca.key.pem",
        "enclaves/governance.p7s",
    ]
    .iter()
    .all(|f| dir.join(f).is_file())
}

/// Creates a keystore in `dir` for DDS domain `domain`: a new authority and the signed governance.
/// Refused where a keystore is already (its authority would be replaced and every enclave orphaned).
pub fn create_keystore(dir: &Path, domain: u32) -> Result<(), Error> {
    if is_keystore(dir) {
        return Err(Error::Exists(dir.to_owned()));
    }
    for sub in [PUBLIC, PRIVATE, ENCLAVES] {
        fs::create_dir_all(dir.join(sub)).map_err(|e| Error::io(&dir.join(sub), e))?;
    }
    let ca = Identity::authority(AUTHORITY_NAME)?;
    write(&dir.join(PRIVATE).join("ca.key.pem"), ca.key_pem()?.as_bytes(), true)?;
    write(&dir.join(PUBLIC).join("ca.cert.pem"), ca.certificate_pem()?.as_bytes(), false)?;
    for role in ["identity_ca", "permissions_ca"] {
        link(Path::new("ca.cert.pem"), &dir.join(PUBLIC).join(format!("{role}.cert.pem")))?;
        link(Path::new("ca.key.pem"), &dir.join(PRIVATE).join(format!("{role}.key.pem")))?;
    }
    let document = governance(domain);
    write(&dir.join(ENCLAVES).join("governance.xml"), document.as_bytes(), false)?;
    write(&dir.join(ENCLAVES).join("governance.p7s"), &smime::sign(&ca, &document)?, false)?;
    Ok(())
}

/// Checks an enclave name as ROS 2 checks a namespace: absolute, tokens of letters, digits and `_`
/// not starting with a digit, no empty token, no trailing `/`.
pub fn check_enclave_name(name: &str) -> Result<(), Error> {
    let bad = |why: &str| Err(Error::EnclaveName(name.to_owned(), why.to_owned()));
    let Some(body) = name.strip_prefix('/') else { return bad("it must start with `/`") };
    if body.is_empty() {
        return Ok(());
    }
    for token in body.split('/') {
        match token.chars().next() {
            None => return bad("it has an empty part (`//` or a trailing `/`)"),
            Some(c) if c.is_ascii_digit() => return bad("a part starts with a digit"),
            _ if !token.chars().all(|c| c.is_ascii_alphanumeric() || c == '_') => {
                return bad("a part holds a character other than letters, digits and `_`");
            }
            _ => {}
        }
    }
    Ok(())
}

/// The folder of enclave `name` in the keystore `dir`.
pub fn enclave_dir(dir: &Path, name: &str) -> PathBuf {
    dir.join(ENCLAVES).join(name.trim_start_matches('/'))
}

/// Creates (or re-signs) the enclave `name` in the keystore `dir` with `grant`: a key and certificate
/// `CN=name` from the keystore's authority (kept if the enclave has them), and its permissions, signed.
/// Re-running it with a smaller grant is how a permission is revoked.
pub fn create_enclave(dir: &Path, name: &str, grant: &Grant, domain: u32) -> Result<PathBuf, Error> {
    check_enclave_name(name)?;
    if !is_keystore(dir) {
        return Err(Error::NoKeystore(dir.to_owned()));
    }
    let read = |p: &Path| fs::read_to_string(p).map_err(|e| Error::io(p, e));
    let ca = Identity::from_pem(
        &read(&dir.join(PRIVATE).join("permissions_ca.key.pem"))?,
        &read(&dir.join(PUBLIC).join("permissions_ca.cert.pem"))?,
    )?;
    let enclave = enclave_dir(dir, name);
    fs::create_dir_all(&enclave).map_err(|e| Error::io(&enclave, e))?;
    let up = relative_root(name);
    for (file, target) in [
        ("identity_ca.cert.pem", up.join(PUBLIC).join("identity_ca.cert.pem")),
        ("permissions_ca.cert.pem", up.join(PUBLIC).join("permissions_ca.cert.pem")),
        ("governance.p7s", up.join(ENCLAVES).join("governance.p7s")),
    ] {
        // The default enclave `/` is the enclaves folder itself, where the governance already is.
        if !(file == "governance.p7s" && name == "/") {
            link(&target, &enclave.join(file))?;
        }
    }
    let (cert_path, key_path) = (enclave.join("cert.pem"), enclave.join("key.pem"));
    let identity = match (cert_path.is_file(), key_path.is_file()) {
        (true, true) => Identity::from_pem(&read(&key_path)?, &read(&cert_path)?)?,
        _ => {
            let id = ca.issue(name)?;
            write(&key_path, id.key_pem()?.as_bytes(), true)?;
            write(&cert_path, id.certificate_pem()?.as_bytes(), false)?;
            id
        }
    };
    let validity = &identity.certificate.tbs_certificate.validity;
    let iso = |t: &x509_cert::time::Time| {
        let d = t.to_date_time();
        format!("{:04}-{:02}-{:02}T{:02}:{:02}:{:02}", d.year(), d.month(), d.day(), d.hour(), d.minutes(), d.seconds())
    };
    let document = grant.permissions(name, domain, &iso(&validity.not_before), &iso(&validity.not_after));
    write(&enclave.join("permissions.xml"), document.as_bytes(), false)?;
    write(&enclave.join("permissions.p7s"), &smime::sign(&ca, &document)?, false)?;
    Ok(enclave)
}

/// `../..` from an enclave's folder to the keystore's root.
fn relative_root(name: &str) -> PathBuf {
    let depth = name.trim_start_matches('/').split('/').filter(|t| !t.is_empty()).count();
    (0..depth + 1).map(|_| "..").collect()
}

/// Writes `bytes` to `path` through a new file moved into place; `private`: mode 0600 from the start.
fn write(path: &Path, bytes: &[u8], private: bool) -> Result<(), Error> {
    let tmp = path.with_extension("tmp");
    let mut options = fs::OpenOptions::new();
    options.write(true).create(true).truncate(true).mode(if private { 0o600 } else { 0o644 });
    let mut f = options.open(&tmp).map_err(|e| Error::io(&tmp, e))?;
    f.write_all(bytes).and_then(|()| f.sync_all()).map_err(|e| Error::io(&tmp, e))?;
    fs::rename(&tmp, path).map_err(|e| Error::io(path, e))
}

/// A relative symbolic link `path` → `target`, replacing what is there.
fn link(target: &Path, path: &Path) -> Result<(), Error> {
    if path.symlink_metadata().is_ok() {
        fs::remove_file(path).map_err(|e| Error::io(path, e))?;
    }
    symlink(target, path).map_err(|e| Error::io(path, e))
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::os::unix::fs::PermissionsExt;

    #[test]
    fn the_layout_is_sros2s_with_private_keys_0600_and_relative_links() {
        let dir = tempfile::tempdir().unwrap();
        let ks = dir.path().join("keystore");
        create_keystore(&ks, 0).unwrap();
        assert!(is_keystore(&ks));
        let mut g = Grant::default();
        g.writes("/chatter");
        let enclave = create_enclave(&ks, "/cell/lwr_control", &g, 0).unwrap();
        assert_eq!(enclave, ks.join("enclaves/cell/lwr_control"));
        for f in ["cert.pem", "key.pem", "permissions.xml", "permissions.p7s"] {
            assert!(enclave.join(f).symlink_metadata().unwrap().is_file(), "{f}");
        }
        for (f, target) in [
            ("identity_ca.cert.pem", "../../../public/identity_ca.cert.pem"),
            ("permissions_ca.cert.pem", "../../../public/permissions_ca.cert.pem"),
            ("governance.p7s", "../../../enclaves/governance.p7s"),
        ] {
            assert_eq!(fs::read_link(enclave.join(f)).unwrap(), Path::new(target));
            assert!(enclave.join(f).is_file(), "{f} resolves");
        }
        for key in [ks.join("private/ca.key.pem"), enclave.join("key.pem")] {
            assert_eq!(fs::metadata(&key).unwrap().permissions().mode() & 0o777, 0o600, "{}", key.display());
        }
        assert_eq!(fs::read_link(ks.join("private/identity_ca.key.pem")).unwrap(), Path::new("ca.key.pem"));
        let permissions = fs::read_to_string(enclave.join("permissions.xml")).unwrap();
        assert!(permissions.contains("CN=/cell/lwr_control") && permissions.contains("<topic>rt/chatter</topic>"));
    }

    #[test]
    fn a_second_keystore_over_the_first_is_refused_and_an_enclave_keeps_its_identity_when_re_signed() {
        let dir = tempfile::tempdir().unwrap();
        create_keystore(dir.path(), 0).unwrap();
        let ca = fs::read(dir.path().join("public/ca.cert.pem")).unwrap();
        assert!(matches!(create_keystore(dir.path(), 0), Err(Error::Exists(_))));
        assert_eq!(fs::read(dir.path().join("public/ca.cert.pem")).unwrap(), ca, "the authority stays");
        let e = create_enclave(dir.path(), "/user", &Grant::everything(), 0).unwrap();
        let cert = fs::read(e.join("cert.pem")).unwrap();
        let before = fs::read_to_string(e.join("permissions.xml")).unwrap();
        create_enclave(dir.path(), "/user", &Grant::default(), 0).unwrap();
        assert_eq!(fs::read(e.join("cert.pem")).unwrap(), cert, "same identity");
        let after = fs::read_to_string(e.join("permissions.xml")).unwrap();
        assert!(before.contains("rt/*") && !after.contains("rt/*"), "the grant re-signed smaller");
    }

    #[test]
    fn enclave_names_are_ros_namespaces_and_need_a_keystore() {
        for good in ["/", "/user", "/a/b_2", "/_x"] {
            check_enclave_name(good).unwrap();
        }
        for bad in ["user", "/a/", "//a", "/a b", "/2a", "/a/../b", "/a-b"] {
            assert!(check_enclave_name(bad).is_err(), "{bad}");
        }
        let dir = tempfile::tempdir().unwrap();
        assert!(matches!(create_enclave(dir.path(), "/user", &Grant::default(), 0), Err(Error::NoKeystore(_))));
        assert_eq!(fs::read_dir(dir.path()).unwrap().count(), 0, "nothing written");
    }
}
