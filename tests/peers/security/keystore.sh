#!/usr/bin/env bash
# Writes an SROS2-layout keystore with the openssl command line, for the interop test of DDS-Security
# (tests/security_interop.rs): one CA (prime256v1) as identity and permissions CA, sros2's default
# governance (no unauthenticated participants, join access control, discovery and liveliness encrypted,
# RTPS messages signed, every topic's data and metadata encrypted, read and write access controlled),
# and per enclave a key (PKCS#8, mode 0600), a certificate whose subject is CN=<enclave> and permissions
# that allow every topic of domains 0–230. S/MIME signatures as `openssl smime -sign -text`, as sros2
# writes them.
#
# Usage: keystore.sh DIR /ENCLAVE...   (DIR/public, DIR/private, DIR/enclaves/ENCLAVE/)
set -euo pipefail
dir="$1"; shift
command -v openssl >/dev/null || { echo "keystore.sh: openssl missing (apt-get install openssl)" >&2; exit 1; }
mkdir -p "$dir/public" "$dir/private" "$dir/enclaves"
cd "$dir"
key() { openssl genpkey -algorithm EC -pkeyopt ec_paramgen_curve:prime256v1 -out "$1" 2>/dev/null; chmod 600 "$1"; }
sign() { openssl smime -sign -text -in "$1" -out "$2" -signer public/ca.cert.pem -inkey private/ca.key.pem; }
key private/ca.key.pem
openssl req -x509 -new -key private/ca.key.pem -sha256 -days 3650 -subj "/CN=softcontact test CA" \
  -out public/ca.cert.pem 2>/dev/null
cp public/ca.cert.pem public/identity_ca.cert.pem
cp public/ca.cert.pem public/permissions_ca.cert.pem
cat > private/governance.xml <<'XML'
<?xml version="1.0" encoding="UTF-8"?>
<dds xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance" xsi:noNamespaceSchemaLocation="http://www.omg.org/spec/DDS-SECURITY/20170901/omg_shared_ca_governance.xsd">
  <domain_access_rules>
    <domain_rule>
      <domains><id_range><min>0</min><max>230</max></id_range></domains>
      <allow_unauthenticated_participants>false</allow_unauthenticated_participants>
      <enable_join_access_control>true</enable_join_access_control>
      <discovery_protection_kind>ENCRYPT</discovery_protection_kind>
      <liveliness_protection_kind>ENCRYPT</liveliness_protection_kind>
      <rtps_protection_kind>SIGN</rtps_protection_kind>
      <topic_access_rules>
        <topic_rule>
          <topic_expression>*</topic_expression>
          <enable_discovery_protection>true</enable_discovery_protection>
          <enable_liveliness_protection>true</enable_liveliness_protection>
          <enable_read_access_control>true</enable_read_access_control>
          <enable_write_access_control>true</enable_write_access_control>
          <metadata_protection_kind>ENCRYPT</metadata_protection_kind>
          <data_protection_kind>ENCRYPT</data_protection_kind>
        </topic_rule>
      </topic_access_rules>
    </domain_rule>
  </domain_access_rules>
</dds>
XML
sign private/governance.xml public/governance.p7s
for enclave in "$@"; do
  e="enclaves${enclave}"
  mkdir -p "$e"
  key "$e/key.pem"
  openssl req -new -key "$e/key.pem" -subj "/CN=\\${enclave}" -out "$e/request.csr" 2>/dev/null
  openssl x509 -req -in "$e/request.csr" -CA public/ca.cert.pem -CAkey private/ca.key.pem -CAserial private/ca.srl -CAcreateserial \
    -days 365 -sha256 -out "$e/cert.pem" 2>/dev/null
  rm "$e/request.csr"
  cp public/identity_ca.cert.pem public/permissions_ca.cert.pem public/governance.p7s "$e/"
  cat > "$e/permissions.xml" <<XML
<?xml version="1.0" encoding="UTF-8"?>
<dds xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance" xsi:noNamespaceSchemaLocation="http://www.omg.org/spec/DDS-SECURITY/20170901/omg_shared_ca_permissions.xsd">
  <permissions>
    <grant name="${enclave}">
      <subject_name>CN=${enclave}</subject_name>
      <validity><not_before>2020-01-01T00:00:00</not_before><not_after>2035-01-01T00:00:00</not_after></validity>
      <allow_rule>
        <domains><id_range><min>0</min><max>230</max></id_range></domains>
        <publish><topics><topic>*</topic></topics></publish>
        <subscribe><topics><topic>*</topic></topics></subscribe>
      </allow_rule>
      <default>DENY</default>
    </grant>
  </permissions>
</dds>
XML
  sign "$e/permissions.xml" "$e/permissions.p7s"
done
