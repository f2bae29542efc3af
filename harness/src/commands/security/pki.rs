//! The test PKI's cryptography and documents, shared by `cortex security init` and `cortex security revoke`: a CA
//! (EC P-256 key, self-signed certificate), identity certificates it signs, the governance and permissions XML, their
//! S/MIME signatures, and the files of one participant's directory. Everything is computed in memory first
//! ([`credentials`]) and written afterwards ([`write_files`]), so a failure while issuing leaves no half-written
//! directory.

use std::path::Path;

use anyhow::{Context, Result};
use openssl::asn1::{Asn1Time, Asn1TimeRef};
use openssl::bn::{BigNum, MsbOption};
use openssl::ec::{EcGroup, EcKey};
use openssl::hash::MessageDigest;
use openssl::nid::Nid;
use openssl::pkcs7::{Pkcs7, Pkcs7Flags};
use openssl::pkey::{PKey, Private};
use openssl::stack::Stack;
use openssl::x509::extension::{BasicConstraints, KeyUsage};
use openssl::x509::{X509, X509Name, X509NameBuilder};

use super::Protection;

/// The CA's files in `DIR/ca/`: its key and its certificate.
pub(super) const CA_KEY: &str = "ca.key.pem";
/// The CA's certificate in `DIR/ca/`.
pub(super) const CA_CERT: &str = "ca.cert.pem";

/// A CA: its key and certificate.
pub(super) struct Authority {
    /// The CA's private key.
    pub key: PKey<Private>,
    /// The CA's self-signed certificate.
    pub cert: X509,
}

impl Authority {
    /// A new CA (fresh key, self-signed certificate `O=cortex, CN=cortex test CA`) valid from a day ago for `days`
    /// days.
    pub fn new(days: i64) -> Result<Authority> {
        let key = ec_key()?;
        let (not_before, not_after) = validity((-1, days))?;
        let cert = certificate(&name("cortex test CA")?, &key, None, (&not_before, &not_after), true)?;
        Ok(Authority { key, cert })
    }

    /// The CA's key and certificate as the files of `DIR/ca/`.
    pub fn files(&self) -> Result<Vec<(&'static str, Vec<u8>)>> {
        Ok(vec![(CA_KEY, self.key.private_key_to_pem_pkcs8()?), (CA_CERT, self.cert.to_pem()?)])
    }
}

fn ec_key() -> Result<PKey<Private>> {
    let group = EcGroup::from_curve_name(Nid::X9_62_PRIME256V1)?;
    Ok(PKey::from_ec_key(EcKey::generate(&group)?)?)
}

fn name(common: &str) -> Result<X509Name> {
    let mut name = X509NameBuilder::new()?;
    name.append_entry_by_text("O", "cortex")?;
    name.append_entry_by_text("CN", common)?;
    Ok(name.build())
}

/// Seconds since the Unix epoch now.
pub(super) fn now_unix() -> Result<i64> {
    Ok(std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH)?.as_secs() as i64)
}

/// Validity from `days.0` to `days.1` days from now (negative: in the past).
pub(super) fn validity(days: (i64, i64)) -> Result<(Asn1Time, Asn1Time)> {
    let now = now_unix()?;
    Ok((Asn1Time::from_unix(now + days.0 * 86_400)?, Asn1Time::from_unix(now + days.1 * 86_400)?))
}

fn certificate(
    subject: &X509Name,
    key: &PKey<Private>,
    issuer: Option<&Authority>,
    (not_before, not_after): (&Asn1TimeRef, &Asn1TimeRef),
    ca: bool,
) -> Result<X509> {
    let mut builder = X509::builder()?;
    builder.set_version(2)?;
    let mut serial = BigNum::new()?;
    serial.rand(64, MsbOption::MAYBE_ZERO, false)?;
    let serial = serial.to_asn1_integer()?;
    builder.set_serial_number(&serial)?;
    builder.set_subject_name(subject)?;
    builder.set_issuer_name(issuer.map_or(subject, |ca| ca.cert.subject_name()))?;
    builder.set_pubkey(key)?;
    builder.set_not_before(not_before)?;
    builder.set_not_after(not_after)?;
    if ca {
        builder.append_extension(BasicConstraints::new().critical().ca().build()?)?;
        builder.append_extension(KeyUsage::new().critical().key_cert_sign().crl_sign().build()?)?;
    } else {
        builder.append_extension(KeyUsage::new().critical().digital_signature().build()?)?;
    }
    builder.sign(issuer.map_or(key, |ca| &ca.key), MessageDigest::sha256())?;
    Ok(builder.build())
}

/// `document` signed by the CA as S/MIME (clear-signed, `text/plain`), as `openssl smime -sign -text` writes it.
pub(super) fn smime_signed(ca: &Authority, document: &str) -> Result<Vec<u8>> {
    let flags = Pkcs7Flags::TEXT | Pkcs7Flags::DETACHED;
    let others: Stack<X509> = Stack::new()?;
    let signed = Pkcs7::sign(&ca.cert, &ca.key, &others, document.as_bytes(), flags)?;
    Ok(signed.to_smime(document.as_bytes(), flags)?)
}

/// The domain governance document (one for every participant) protecting submessages as `protection` says.
pub(super) fn governance(protection: Protection) -> String {
    let metadata = match protection {
        Protection::Encrypt => "ENCRYPT",
        Protection::Sign => "SIGN",
    };
    format!(
        r#"<?xml version="1.0" encoding="UTF-8"?>
<dds xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance"
     xsi:noNamespaceSchemaLocation="http://www.omg.org/spec/DDS-SECURITY/20170901/omg_shared_ca_governance.xsd">
  <domain_access_rules>
    <domain_rule>
      <domains><id_range><min>0</min><max>232</max></id_range></domains>
      <allow_unauthenticated_participants>false</allow_unauthenticated_participants>
      <enable_join_access_control>true</enable_join_access_control>
      <discovery_protection_kind>ENCRYPT</discovery_protection_kind>
      <liveliness_protection_kind>ENCRYPT</liveliness_protection_kind>
      <rtps_protection_kind>NONE</rtps_protection_kind>
      <topic_access_rules>
        <topic_rule>
          <topic_expression>*</topic_expression>
          <enable_discovery_protection>true</enable_discovery_protection>
          <enable_liveliness_protection>true</enable_liveliness_protection>
          <enable_read_access_control>true</enable_read_access_control>
          <enable_write_access_control>true</enable_write_access_control>
          <metadata_protection_kind>{metadata}</metadata_protection_kind>
          <data_protection_kind>NONE</data_protection_kind>
        </topic_rule>
      </topic_access_rules>
    </domain_rule>
  </domain_access_rules>
</dds>
"#
    )
}

/// A permissions document of one grant for `common` (subject `CN=common,O=cortex`): subscribe `topics`, and publish
/// `topics` (a writer) or the requests topic among them alone (a reader).
pub(super) fn permissions(common: &str, topics: &str, may_publish: bool, days: (i64, i64)) -> Result<String> {
    let now = now_unix()?;
    let (not_before, not_after) = (utc_text(now + days.0 * 86_400), utc_text(now + days.1 * 86_400));
    let topic = format!("<topics><topic>{topics}</topic></topics>");
    let published = if may_publish { topics.to_owned() } else { super::requests_topic(topics) };
    let publish = format!("<publish><topics><topic>{published}</topic></topics></publish>");
    Ok(format!(
        r#"<?xml version="1.0" encoding="UTF-8"?>
<dds xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance"
     xsi:noNamespaceSchemaLocation="http://www.omg.org/spec/DDS-Security/20170901/omg_shared_ca_permissions.xsd">
  <permissions>
    <grant name="{common}">
      <subject_name>{}</subject_name>
      <validity><not_before>{not_before}</not_before><not_after>{not_after}</not_after></validity>
      <allow_rule>
        <domains><id_range><min>0</min><max>232</max></id_range></domains>
        {publish}
        <subscribe>{topic}</subscribe>
      </allow_rule>
      <default>DENY</default>
    </grant>
  </permissions>
</dds>
"#,
        subject(common)
    ))
}

/// The subject name a permissions grant names for participant `common`.
pub(super) fn subject(common: &str) -> String {
    format!("CN={common},O=cortex")
}

/// `unix_seconds` as `YYYY-MM-DDTHH:MM:SS` (UTC), the permissions document's time format.
pub(super) fn utc_text(unix_seconds: i64) -> String {
    let days = unix_seconds.div_euclid(86_400);
    let second_of_day = unix_seconds.rem_euclid(86_400);
    // Civil date from days since 1970-01-01 (Howard Hinnant's algorithm).
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z.rem_euclid(146_097);
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let day = doy - (153 * mp + 2) / 5 + 1;
    let month = if mp < 10 { mp + 3 } else { mp - 9 };
    let year = yoe + era * 400 + i64::from(month <= 2);
    format!(
        "{year:04}-{month:02}-{day:02}T{:02}:{:02}:{:02}",
        second_of_day / 3600,
        second_of_day / 60 % 60,
        second_of_day % 60
    )
}

/// The files of participant `common`'s directory issued by `ca`: a fresh key, an identity certificate
/// (`O=cortex, CN=common`) valid over `lifetime`, the CA's certificate as identity and permissions CA, the signed
/// governance, and `permissions_xml` with its S/MIME signature.
pub(super) fn credentials(
    ca: &Authority,
    governance_signed: &[u8],
    common: &str,
    lifetime: (&Asn1TimeRef, &Asn1TimeRef),
    permissions_xml: &str,
) -> Result<Vec<(&'static str, Vec<u8>)>> {
    let key = ec_key()?;
    let cert = certificate(&name(common)?, &key, Some(ca), lifetime, false)?;
    Ok(vec![
        ("identity_ca.cert.pem", ca.cert.to_pem()?),
        ("permissions_ca.cert.pem", ca.cert.to_pem()?),
        ("governance.p7s", governance_signed.to_vec()),
        ("cert.pem", cert.to_pem()?),
        ("key.pem", key.private_key_to_pem_pkcs8()?),
        ("permissions.xml", permissions_xml.as_bytes().to_vec()),
        ("permissions.p7s", smime_signed(ca, permissions_xml)?),
    ])
}

/// Writes `bytes` to `path`.
pub(super) fn write(path: &Path, bytes: &[u8]) -> Result<()> {
    std::fs::write(path, bytes).with_context(|| format!("writing {}", path.display()))
}

/// Creates `dir` (if needed) and writes `files` into it.
pub(super) fn write_files(dir: &Path, files: &[(&str, Vec<u8>)]) -> Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    for (file, bytes) in files {
        write(&dir.join(file), bytes)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn utc_text_formats_known_instants() {
        assert_eq!(utc_text(0), "1970-01-01T00:00:00");
        assert_eq!(utc_text(951_782_400), "2000-02-29T00:00:00");
        assert_eq!(utc_text(1_700_000_000), "2023-11-14T22:13:20");
    }
}
