//! A Cyclone DDS 0.10 configuration with DDS-Security, for the tests whose Cyclone peers join a keystore
//! that `softcontact security` wrote.

use std::path::{Path, PathBuf};

/// Where Debian's Cyclone DDS keeps its security plugins: libddsc0debian's own folder of the multiarch
/// library directory, off the default search path, so the configuration names each library in full.
pub fn cyclone_plugins() -> PathBuf {
    std::fs::read_dir("/usr/lib")
        .unwrap()
        .filter_map(|e| e.ok())
        .map(|e| e.path().join("libddsc0debian"))
        .find(|d| d.join("libdds_security_auth.so").is_file())
        .expect("Cyclone DDS's security plugins (libddsc0debian) are installed")
}

/// A Cyclone DDS configuration on `lo` with multicast, and DDS-Security from `enclave` (a keystore's
/// `enclaves/<name>` folder) when there is one.
pub fn cyclone_config(enclave: Option<&Path>) -> String {
    let security = enclave.map_or(String::new(), |e| {
        let lib = cyclone_plugins();
        let (lib, e) = (lib.display(), e.display());
        format!(
            "<Security>\
             <Authentication><Library path=\"{lib}/libdds_security_auth.so\" initFunction=\"init_authentication\" \
             finalizeFunction=\"finalize_authentication\"/>\
             <IdentityCA>file:{e}/identity_ca.cert.pem</IdentityCA>\
             <IdentityCertificate>file:{e}/cert.pem</IdentityCertificate>\
             <PrivateKey>file:{e}/key.pem</PrivateKey></Authentication>\
             <AccessControl><Library path=\"{lib}/libdds_security_ac.so\" initFunction=\"init_access_control\" \
             finalizeFunction=\"finalize_access_control\"/>\
             <PermissionsCA>file:{e}/permissions_ca.cert.pem</PermissionsCA>\
             <Governance>file:{e}/governance.p7s</Governance>\
             <Permissions>file:{e}/permissions.p7s</Permissions></AccessControl>\
             <Cryptographic><Library path=\"{lib}/libdds_security_crypto.so\" initFunction=\"init_crypto\" \
             finalizeFunction=\"finalize_crypto\"/></Cryptographic>\
             </Security>"
        )
    });
    format!(
        "<CycloneDDS><Domain id=\"any\"><General><Interfaces><NetworkInterface name=\"lo\" multicast=\"true\"/>\
         </Interfaces></General>{security}</Domain></CycloneDDS>"
    )
}
