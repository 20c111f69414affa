//! ROS 2 security (SROS2 over DDS-Security 1.1) for the softcontact graph: keystores as
//! `ros2 security` writes them, with one certificate authority, an identity per enclave (one enclave a
//! process), sros2's governance, and permissions that grant each enclave what its nodes publish and
//! subscribe and nothing else — signed as S/MIME by that authority, so that any vendor's DDS-Security
//! plugins (RustDDS's, Cyclone DDS's, Fast DDS's) read them.
//!
//! - [`pki`]: P-256 keys, the authority's and the enclaves' X.509 certificates.
//! - [`smime`]: a document signed as `openssl smime -sign -text` signs it.
//! - [`policy`]: the governance and permissions documents, and [`policy::Grant`], what one enclave may
//!   publish and subscribe, in DDS names.
//! - [`keystore`]: the folder layout, `create_keystore` and `create_enclave`.
//!
//! References: OMG, *DDS Security* 1.1 (2018), §9.3 (builtin authentication), §9.4 (builtin access
//! control); ros2/sros2 (the keystore layout and the default governance); ros2/design, *Topic and
//! Service name mapping to DDS*.

pub mod keystore;
pub mod pki;
pub mod policy;
pub mod smime;

use std::path::{Path, PathBuf};

pub use keystore::{check_enclave_name, create_enclave, create_keystore, enclave_dir, is_keystore};
pub use policy::Grant;

#[derive(Debug, thiserror::Error)]
pub enum Error {
    #[error("{0}: {1}")]
    Io(PathBuf, std::io::Error),
    #[error("{0} already holds a keystore; its authority is kept (remove the folder to start anew)")]
    Exists(PathBuf),
    #[error("{0} holds no keystore (create one with `softcontact security create-keystore {0}`)")]
    NoKeystore(PathBuf),
    #[error("enclave name {0:?}: {1} (a ROS 2 namespace such as /user or /cell/lwr_control)")]
    EnclaveName(String, String),
    #[error("keys and certificates: {0}")]
    Encoding(String),
}

impl Error {
    fn io(path: &Path, e: std::io::Error) -> Self {
        Error::Io(path.to_owned(), e)
    }
}
