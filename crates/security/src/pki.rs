//! Keys and certificates of a keystore: one certificate authority, self-signed, and the identity
//! certificate of each enclave, issued by it. P-256 keys and ECDSA-SHA256 signatures, as DDS-Security
//! 1.1 §9.3.1 (prime256v1) and sros2 (`_utilities.build_key_and_cert`) have them: valid from a day
//! before now (a peer whose clock is a little behind still accepts it) for ten years; the authority's
//! subject `CN=sros2CA`, an enclave's `CN=<enclave name>`.

use std::str::FromStr;
use std::time::{Duration, SystemTime};

use der::referenced::OwnedToRef;
use der::{DecodePem, EncodePem, pem::LineEnding};
use p256::ecdsa::{DerSignature, SigningKey};
use p256::pkcs8::{DecodePrivateKey, EncodePrivateKey};
use rand_core::{OsRng, RngCore};
use x509_cert::Certificate;
use x509_cert::builder::{Builder, CertificateBuilder, Profile};
use x509_cert::ext::pkix::{BasicConstraints, SubjectKeyIdentifier};
use x509_cert::name::Name;
use x509_cert::serial_number::SerialNumber;
use x509_cert::spki::SubjectPublicKeyInfoOwned;
use x509_cert::time::{Time, Validity};

use crate::Error;

/// The authority's common name, sros2's.
pub const AUTHORITY_NAME: &str = "sros2CA";
/// How long a certificate is valid, as sros2 makes them.
pub const LIFETIME: Duration = Duration::from_secs(3650 * 86_400);
/// How far before now a certificate's validity starts.
pub const BACKDATE: Duration = Duration::from_secs(86_400);

/// A private key and the certificate of its public key.
pub struct Identity {
    pub key: SigningKey,
    pub certificate: Certificate,
}

impl Identity {
    /// A new self-signed certificate authority named `common_name`.
    pub fn authority(common_name: &str) -> Result<Self, Error> {
        let key = SigningKey::random(&mut OsRng);
        let certificate = issue(Profile::Manual { issuer: None }, common_name, &key, &key)?;
        Ok(Identity { key, certificate })
    }

    /// A new key with its certificate `CN=common_name`, issued by this authority.
    pub fn issue(&self, common_name: &str) -> Result<Identity, Error> {
        let key = SigningKey::random(&mut OsRng);
        let profile = Profile::Leaf {
            issuer: self.certificate.tbs_certificate.subject.clone(),
            enable_key_agreement: false,
            enable_key_encipherment: false,
            include_subject_key_identifier: true,
        };
        let certificate = issue(profile, common_name, &key, &self.key)?;
        Ok(Identity { key, certificate })
    }

    /// The key as PKCS #8 PEM (unencrypted, as sros2 writes it).
    pub fn key_pem(&self) -> Result<String, Error> {
        Ok(self.key.to_pkcs8_pem(LineEnding::LF).map_err(|e| Error::Encoding(e.to_string()))?.to_string())
    }

    pub fn certificate_pem(&self) -> Result<String, Error> {
        self.certificate.to_pem(LineEnding::LF).map_err(|e| Error::Encoding(e.to_string()))
    }

    /// An identity read back from its key and certificate PEM; the key must be the certificate's.
    pub fn from_pem(key_pem: &str, certificate_pem: &str) -> Result<Self, Error> {
        let key = SigningKey::from_pkcs8_pem(key_pem).map_err(|e| Error::Encoding(format!("the key: {e}")))?;
        let certificate =
            Certificate::from_pem(certificate_pem).map_err(|e| Error::Encoding(format!("the certificate: {e}")))?;
        let public = SubjectPublicKeyInfoOwned::from_key(*key.verifying_key())
            .map_err(|e| Error::Encoding(format!("the key: {e}")))?;
        if public != certificate.tbs_certificate.subject_public_key_info {
            return Err(Error::Encoding("the key is not the certificate's".into()));
        }
        Ok(Identity { key, certificate })
    }
}

fn issue(profile: Profile, common_name: &str, subject: &SigningKey, issuer: &SigningKey) -> Result<Certificate, Error> {
    let encoding = |e: &dyn std::fmt::Display| Error::Encoding(e.to_string());
    let now = SystemTime::now();
    let validity = Validity {
        not_before: Time::try_from(now - BACKDATE).map_err(|e| encoding(&e))?,
        not_after: Time::try_from(now + LIFETIME).map_err(|e| encoding(&e))?,
    };
    let name = Name::from_str(&format!("CN={}", escape(common_name))).map_err(|e| encoding(&e))?;
    let public = SubjectPublicKeyInfoOwned::from_key(*subject.verifying_key()).map_err(|e| encoding(&e))?;
    let authority = matches!(profile, Profile::Manual { issuer: None });
    let mut builder =
        CertificateBuilder::new(profile, serial(), validity, name, public.clone(), issuer).map_err(|e| encoding(&e))?;
    if authority {
        // sros2's authority: a CA for one level below it, with no key usage named (a key usage of
        // certificate signing alone would make it unfit to sign the S/MIME documents it signs).
        builder
            .add_extension(&BasicConstraints { ca: true, path_len_constraint: Some(1) })
            .map_err(|e| encoding(&e))?;
        let id = SubjectKeyIdentifier::try_from(public.owned_to_ref()).map_err(|e| encoding(&e))?;
        builder.add_extension(&id).map_err(|e| encoding(&e))?;
    }
    builder.build::<DerSignature>().map_err(|e| encoding(&e))
}

/// A random positive serial number of 20 octets (RFC 5280 §4.1.2.2's most).
fn serial() -> SerialNumber {
    let mut bytes = [0u8; 20];
    OsRng.fill_bytes(&mut bytes);
    bytes[0] = (bytes[0] & 0x7f) | 0x01;
    SerialNumber::new(&bytes).expect("20 octets, positive")
}

/// A common name as an RFC 4514 string value: `,+"\<>;=` escaped.
fn escape(value: &str) -> String {
    let mut out = String::with_capacity(value.len());
    for c in value.chars() {
        if ",+\"\\<>;=".contains(c) {
            out.push('\\');
        }
        out.push(c);
    }
    out
}

/// The certificate's subject common name, as a string.
pub fn common_name(certificate: &Certificate) -> Option<String> {
    use der::asn1::{PrintableStringRef, Utf8StringRef};
    let cn = const_oid_cn();
    certificate.tbs_certificate.subject.0.iter().flat_map(|rdn| rdn.0.iter()).find(|a| a.oid == cn).and_then(|a| {
        a.value
            .decode_as::<Utf8StringRef<'_>>()
            .map(|s| s.as_str().to_owned())
            .or_else(|_| a.value.decode_as::<PrintableStringRef<'_>>().map(|s| s.as_str().to_owned()))
            .ok()
    })
}

fn const_oid_cn() -> der::oid::ObjectIdentifier {
    der::oid::ObjectIdentifier::new_unwrap("2.5.4.3")
}

#[cfg(test)]
mod tests {
    use super::*;
    use p256::ecdsa::VerifyingKey;
    use p256::ecdsa::signature::Verifier;

    fn verify(issuer: &Certificate, certificate: &Certificate) -> bool {
        use der::Encode;
        let key = VerifyingKey::from_sec1_bytes(
            issuer.tbs_certificate.subject_public_key_info.subject_public_key.raw_bytes(),
        )
        .unwrap();
        let tbs = certificate.tbs_certificate.to_der().unwrap();
        let signature = p256::ecdsa::DerSignature::from_bytes(certificate.signature.raw_bytes()).unwrap();
        key.verify(&tbs, &signature).is_ok()
    }

    fn basic_constraints(certificate: &Certificate) -> BasicConstraints {
        use der::Decode;
        let ext = certificate.tbs_certificate.extensions.as_ref().unwrap();
        let bc = ext.iter().find(|e| e.extn_id == der::oid::ObjectIdentifier::new_unwrap("2.5.29.19")).unwrap();
        BasicConstraints::from_der(bc.extn_value.as_bytes()).unwrap()
    }

    #[test]
    fn the_authority_signs_itself_and_each_enclave_and_is_the_only_ca() {
        let ca = Identity::authority(AUTHORITY_NAME).unwrap();
        let enclave = ca.issue("/lwr_control").unwrap();
        assert!(verify(&ca.certificate, &ca.certificate));
        assert!(verify(&ca.certificate, &enclave.certificate));
        let stranger = Identity::authority(AUTHORITY_NAME).unwrap();
        assert!(!verify(&stranger.certificate, &enclave.certificate), "another authority of the same name");
        assert!(basic_constraints(&ca.certificate).ca);
        assert!(!basic_constraints(&enclave.certificate).ca);
        assert_eq!(common_name(&enclave.certificate).as_deref(), Some("/lwr_control"));
        assert_eq!(enclave.certificate.tbs_certificate.issuer, ca.certificate.tbs_certificate.subject);
        assert_ne!(enclave.certificate.tbs_certificate.serial_number, ca.certificate.tbs_certificate.serial_number);
    }

    #[test]
    fn keys_and_certificates_come_back_from_their_pem_and_a_foreign_key_is_refused() {
        let ca = Identity::authority(AUTHORITY_NAME).unwrap();
        let back = Identity::from_pem(&ca.key_pem().unwrap(), &ca.certificate_pem().unwrap()).unwrap();
        assert_eq!(back.certificate, ca.certificate);
        assert_eq!(back.key.verifying_key(), ca.key.verifying_key());
        let other = Identity::authority(AUTHORITY_NAME).unwrap();
        let e = Identity::from_pem(&other.key_pem().unwrap(), &ca.certificate_pem().unwrap()).err().unwrap();
        assert!(e.to_string().contains("not the certificate's"), "{e}");
        assert!(ca.key_pem().unwrap().starts_with("-----BEGIN PRIVATE KEY-----"));
    }

    #[test]
    fn names_with_rfc4514_specials_survive() {
        let ca = Identity::authority(AUTHORITY_NAME).unwrap();
        let odd = ca.issue("/a,b=c+d").unwrap();
        assert_eq!(common_name(&odd.certificate).as_deref(), Some("/a,b=c+d"));
    }
}
