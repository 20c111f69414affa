//! A document signed by the permissions authority as DDS-Security's access control reads it (DDS-Security
//! 1.1 §9.4.1.2.3 and §9.4.1.3: "signed by the Permissions CA in S/MIME format"): `multipart/signed`
//! with the document as its `text/plain` part and a detached CMS SignedData (RFC 5652) beside it — what
//! `openssl smime -sign -text` and sros2 (`_utilities._sign_bytes`, PKCS7 with `Text` and
//! `DetachedSignature`) write.
//!
//! The signed bytes are the text part as MIME canonicalises it: `Content-Type: text/plain`, an empty
//! line, then the document with every line ended by CRLF. The SignedData carries the authority's
//! certificate, names it by issuer and serial number, and signs the content type, the signing time and
//! the SHA-256 digest of those bytes with ECDSA-SHA256.

use base64::Engine;
use cms::builder::{SignedDataBuilder, SignerInfoBuilder, create_signing_time_attribute};
use cms::cert::{CertificateChoices, IssuerAndSerialNumber};
use cms::signed_data::{EncapsulatedContentInfo, SignerIdentifier};
use der::Encode;
use p256::ecdsa::{DerSignature, SigningKey};
use rand_core::{OsRng, RngCore};
use sha2::{Digest, Sha256};
use x509_cert::spki::AlgorithmIdentifierOwned;

use crate::Error;
use crate::pki::Identity;

const ID_DATA: der::oid::ObjectIdentifier = der::oid::ObjectIdentifier::new_unwrap("1.2.840.113549.1.7.1");
const ID_SHA256: der::oid::ObjectIdentifier = der::oid::ObjectIdentifier::new_unwrap("2.16.840.1.101.3.4.2.1");

/// The bytes the signature covers: the text part's header and the document in CRLF lines.
pub fn canonical_text(document: &str) -> Vec<u8> {
    let mut out = b"Content-Type: text/plain\r\n\r\n".to_vec();
    for line in document.split_inclusive('\n') {
        out.extend_from_slice(line.trim_end_matches(['\n', '\r']).as_bytes());
        if line.ends_with('\n') {
            out.extend_from_slice(b"\r\n");
        }
    }
    out
}

/// `document` signed by `signer` as S/MIME (`multipart/signed`, the signature detached).
pub fn sign(signer: &Identity, document: &str) -> Result<Vec<u8>, Error> {
    let signed = canonical_text(document);
    let der = signed_data(signer, &signed)?;
    let mut token = [0u8; 16];
    OsRng.fill_bytes(&mut token);
    let boundary: String = token.iter().map(|b| format!("{b:02X}")).collect();
    let base64 = base64::engine::general_purpose::STANDARD.encode(&der);
    let mut out = Vec::with_capacity(signed.len() + base64.len() + 600);
    out.extend_from_slice(
        format!(
            "MIME-Version: 1.0\nContent-Type: multipart/signed; protocol=\"application/x-pkcs7-signature\"; \
             micalg=\"sha-256\"; boundary=\"----{boundary}\"\n\nThis is an S/MIME signed message\n\n------{boundary}\n"
        )
        .as_bytes(),
    );
    out.extend_from_slice(&signed);
    out.extend_from_slice(
        format!(
            "\n------{boundary}\nContent-Type: application/x-pkcs7-signature; name=\"smime.p7s\"\n\
             Content-Transfer-Encoding: base64\nContent-Disposition: attachment; filename=\"smime.p7s\"\n\n"
        )
        .as_bytes(),
    );
    for chunk in base64.as_bytes().chunks(64) {
        out.extend_from_slice(chunk);
        out.push(b'\n');
    }
    out.extend_from_slice(format!("\n------{boundary}--\n\n").as_bytes());
    Ok(out)
}

/// The DER of a ContentInfo holding the detached SignedData over `content`.
fn signed_data(signer: &Identity, content: &[u8]) -> Result<Vec<u8>, Error> {
    let failed = |what: &str, e: &dyn std::fmt::Display| Error::Encoding(format!("{what}: {e}"));
    let digest = Sha256::digest(content);
    let sha256 = AlgorithmIdentifierOwned { oid: ID_SHA256, parameters: None };
    let encapsulated = EncapsulatedContentInfo { econtent_type: ID_DATA, econtent: None };
    let tbs = &signer.certificate.tbs_certificate;
    let sid = SignerIdentifier::IssuerAndSerialNumber(IssuerAndSerialNumber {
        issuer: tbs.issuer.clone(),
        serial_number: tbs.serial_number.clone(),
    });
    let mut info = SignerInfoBuilder::new(&signer.key, sid, sha256.clone(), &encapsulated, Some(digest.as_slice()))
        .map_err(|e| failed("signer", &e))?;
    info.add_signed_attribute(create_signing_time_attribute().map_err(|e| failed("signing time", &e))?)
        .map_err(|e| failed("signing time", &e))?;
    let content_info = SignedDataBuilder::new(&encapsulated)
        .add_digest_algorithm(sha256)
        .map_err(|e| failed("digest", &e))?
        .add_certificate(CertificateChoices::Certificate(signer.certificate.clone()))
        .map_err(|e| failed("certificate", &e))?
        .add_signer_info::<SigningKey, DerSignature>(info)
        .map_err(|e| failed("signature", &e))?
        .build()
        .map_err(|e| failed("SignedData", &e))?;
    content_info.to_der().map_err(|e| failed("SignedData", &e))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pki::{AUTHORITY_NAME, Identity};

    #[test]
    fn the_text_part_is_canonical_crlf_lines_behind_its_header() {
        assert_eq!(canonical_text("a\nb\n"), b"Content-Type: text/plain\r\n\r\na\r\nb\r\n");
        assert_eq!(canonical_text("a\r\nb"), b"Content-Type: text/plain\r\n\r\na\r\nb");
    }

    #[test]
    fn the_signature_is_multipart_signed_with_a_detached_signed_data() {
        use der::Decode;
        let ca = Identity::authority(AUTHORITY_NAME).unwrap();
        let out = String::from_utf8(sign(&ca, "<dds/>\n").unwrap()).unwrap();
        assert!(out.starts_with("MIME-Version: 1.0\nContent-Type: multipart/signed;"), "{out}");
        assert!(out.contains("\nContent-Type: text/plain\r\n\r\n<dds/>\r\n\n------"), "{out}");
        let b64: String =
            out.split("filename=\"smime.p7s\"\n\n").nth(1).unwrap().lines().take_while(|l| !l.is_empty()).collect();
        let der = base64::engine::general_purpose::STANDARD.decode(b64).unwrap();
        let info = cms::content_info::ContentInfo::from_der(&der).unwrap();
        let signed: cms::signed_data::SignedData = info.content.decode_as().unwrap();
        assert!(signed.encap_content_info.econtent.is_none(), "detached");
        assert_eq!(signed.signer_infos.0.len(), 1);
        assert_eq!(signed.certificates.unwrap().0.len(), 1);
    }
}
