//! `cortex security init DIR`: a small test PKI for DDS Security (issue 22), in the layout of ROS 2 security
//! enclaves, which `cortex agent --security DIR/NAME` and `cortex inspect --security DIR/NAME` read
//! (`transport::rtps::SecurityFiles`).
//!
//! One CA (`DIR/ca/`, key and self-signed certificate; it is both the identity CA and the permissions CA) signs
//! every participant's identity certificate (EC P-256, subject `O=cortex, CN=NAME`) and, as S/MIME, the domain
//! governance and every participant's permissions document. Each participant gets a directory `DIR/NAME/` with the
//! six files the builtin plugins read: `identity_ca.cert.pem`, `permissions_ca.cert.pem`, `governance.p7s`,
//! `cert.pem`, `key.pem` (unencrypted) and `permissions.p7s`, plus the unsigned XML beside them for reading.
//!
//! - Governance (one for all): unauthenticated participants refused, join access control on, discovery and
//!   liveliness encrypted; on every topic read and write access control on, and every submessage (metadata: the
//!   DATA submessage with its payload, heartbeats, acknowledgements) protected as `--protection` says
//!   (`encrypt`: AES-GCM; `sign`: AES-GMAC authentication only). The payload-only protection
//!   (`data_protection_kind`) stays NONE: with it, `rustdds` 0.15 delivered no sample between two agents (seen
//!   with ENCRYPT and SIGN alike: its receivers fail to decode, "ring crypto library gives 'Unspecified' error"),
//!   while submessage protection, which covers the payload too, works.
//! - Permissions: a writer (`--agents`) may publish and subscribe every topic of the topic prefix on every domain;
//!   a reader (`--readers`) may subscribe every topic and publish on the requests topic alone (`PREFIX_requests`,
//!   `transport::Channel::Requests`), which carries only messages that ask (graph requests, announces,
//!   missing-requests) and which agents refuse anything else on. So a reader joins a graph and follows it —
//!   `cortex inspect --security DIR/READER` sees that its permissions grant no more and starts read-only
//!   ([`may_write_graph`]) — but cannot create a writer of updates or answers, and nothing it publishes can
//!   change a graph. A participant named in `--expired` gets an identity certificate and a grant that ended a day
//!   ago.
//!
//! All the cryptography is the `openssl` crate's (the OpenSSL that `rustdds`'s `security` feature links): keys,
//! certificates, S/MIME signatures. Revocation lists are not offered: `rustdds` 0.15 does not read them
//! (`DomainParticipantSecurityConfigFiles::certificate_revocation_list` is "not yet implemented").

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use clap::{Args, Subcommand, ValueEnum};
use openssl::asn1::Asn1Time;
use openssl::bn::{BigNum, MsbOption};
use openssl::ec::{EcGroup, EcKey};
use openssl::hash::MessageDigest;
use openssl::nid::Nid;
use openssl::pkcs7::{Pkcs7, Pkcs7Flags};
use openssl::pkey::{PKey, Private};
use openssl::stack::Stack;
use openssl::x509::extension::{BasicConstraints, KeyUsage};
use openssl::x509::{X509, X509Name, X509NameBuilder};

/// Arguments of `cortex security`.
#[derive(Debug, Args)]
pub struct SecurityArgs {
    #[command(subcommand)]
    command: SecurityCommand,
}

#[derive(Debug, Subcommand)]
enum SecurityCommand {
    /// Create a test PKI: a CA, per-participant identities and permissions, a signed governance document.
    Init(InitArgs),
    /// Check a participant's credentials as an agent would before joining (files present, certificate and grant
    /// valid now, signed by the CA).
    Check(CheckArgs),
}

/// Arguments of `cortex security init`.
#[derive(Debug, Args)]
pub struct InitArgs {
    /// The directory to create (it must not hold a PKI already).
    pub dir: PathBuf,
    /// Participants that may publish and subscribe (one directory each).
    #[arg(long, value_delimiter = ',', default_value = "agent1,agent2,agent3")]
    pub agents: Vec<String>,
    /// Participants that may only read the graph (e.g. an inspector): they subscribe every topic and publish on the
    /// requests topic alone (asking for the graph), so nothing they publish can change it.
    #[arg(long, value_delimiter = ',', default_value = "inspector")]
    pub readers: Vec<String>,
    /// Participants (among the above) whose certificate and permissions grant ended a day ago.
    #[arg(long, value_delimiter = ',')]
    pub expired: Vec<String>,
    /// Topic prefix the permissions name (`PREFIX_*`); `*` for every topic.
    #[arg(long, default_value = "*")]
    pub topic_prefix: String,
    /// How the governance protects every topic's samples.
    #[arg(long, value_enum, default_value_t = Protection::Encrypt)]
    pub protection: Protection,
    /// Validity of the CA, certificates and grants, days.
    #[arg(long, default_value_t = 365)]
    pub days: u32,
}

/// `--protection`: the governance's protection kinds.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum Protection {
    /// AES-GCM encryption (and authentication) of every submessage, payloads included.
    Encrypt,
    /// AES-GMAC authentication of every submessage, no encryption.
    Sign,
}

/// Arguments of `cortex security check`.
#[derive(Debug, Args)]
pub struct CheckArgs {
    /// A participant's directory (`DIR/NAME` of `cortex security init`).
    pub dir: PathBuf,
}

/// Runs `cortex security`.
pub fn run(args: SecurityArgs) -> Result<()> {
    match args.command {
        SecurityCommand::Init(args) => {
            for line in init(&args)? {
                println!("{line}");
            }
            Ok(())
        }
        SecurityCommand::Check(args) => {
            let summary = check_credentials(&args.dir)?;
            println!("{}: {summary}", args.dir.display());
            Ok(())
        }
    }
}

/// A CA: its key and certificate.
struct Authority {
    key: PKey<Private>,
    cert: X509,
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

/// Validity from `days_from_now.0` to `days_from_now.1` days from now (negative: in the past).
fn validity(days: (i64, i64)) -> Result<(Asn1Time, Asn1Time)> {
    let now = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH)?.as_secs() as i64;
    Ok((Asn1Time::from_unix(now + days.0 * 86_400)?, Asn1Time::from_unix(now + days.1 * 86_400)?))
}

fn certificate(
    subject: &X509Name,
    key: &PKey<Private>,
    issuer: Option<&Authority>,
    days: (i64, i64),
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
    let (not_before, not_after) = validity(days)?;
    builder.set_not_before(&not_before)?;
    builder.set_not_after(&not_after)?;
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
fn smime_signed(ca: &Authority, document: &str) -> Result<Vec<u8>> {
    let flags = Pkcs7Flags::TEXT | Pkcs7Flags::DETACHED;
    let others: Stack<X509> = Stack::new()?;
    let signed = Pkcs7::sign(&ca.cert, &ca.key, &others, document.as_bytes(), flags)?;
    Ok(signed.to_smime(document.as_bytes(), flags)?)
}

fn governance(protection: Protection) -> String {
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
fn permissions(common: &str, topics: &str, may_publish: bool, days: (i64, i64)) -> Result<String> {
    let format = |time: i64| {
        let seconds = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH)?.as_secs() as i64;
        let at = seconds + time * 86_400;
        Ok::<String, anyhow::Error>(utc_text(at))
    };
    let (not_before, not_after) = (format(days.0)?, format(days.1)?);
    let topic = format!("<topics><topic>{topics}</topic></topics>");
    let published = if may_publish { topics.to_owned() } else { requests_topic(topics) };
    let publish = format!("<publish><topics><topic>{published}</topic></topics></publish>");
    Ok(format!(
        r#"<?xml version="1.0" encoding="UTF-8"?>
<dds xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance"
     xsi:noNamespaceSchemaLocation="http://www.omg.org/spec/DDS-Security/20170901/omg_shared_ca_permissions.xsd">
  <permissions>
    <grant name="{common}">
      <subject_name>CN={common},O=cortex</subject_name>
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
"#
    ))
}

/// `unix_seconds` as `YYYY-MM-DDTHH:MM:SS` (UTC), the permissions document's time format.
fn utc_text(unix_seconds: i64) -> String {
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

fn write(path: &Path, bytes: &[u8]) -> Result<()> {
    std::fs::write(path, bytes).with_context(|| format!("writing {}", path.display()))
}

fn valid_name(name: &str) -> bool {
    !name.is_empty() && name != "ca" && name.bytes().all(|b| b.is_ascii_alphanumeric() || b == b'-' || b == b'_')
}

/// Creates the PKI `args` describe; returns one line per directory made (what it may do).
///
/// # Errors
/// A bad participant name or topic prefix, an existing PKI in the directory, or a file that cannot be written.
pub fn init(args: &InitArgs) -> Result<Vec<String>> {
    let mut made = Vec::new();
    let names: Vec<(&String, bool)> =
        args.agents.iter().map(|n| (n, true)).chain(args.readers.iter().map(|n| (n, false))).collect();
    for (name, _) in &names {
        if !valid_name(name) {
            bail!("participant name {name:?}: use letters, digits, '-' and '_' (and not \"ca\")");
        }
    }
    if let Some(unknown) = args.expired.iter().find(|e| !names.iter().any(|(n, _)| n == e)) {
        bail!("--expired {unknown}: not among --agents or --readers");
    }
    if args.dir.join("ca").exists() {
        bail!("{} already holds a PKI (ca/); choose another directory", args.dir.display());
    }
    if !(args.topic_prefix == "*" || valid_name(&args.topic_prefix)) {
        bail!("--topic-prefix {:?}: use letters, digits, '-' and '_', or *", args.topic_prefix);
    }
    let days = i64::from(args.days.max(1));
    let ca_dir = args.dir.join("ca");
    std::fs::create_dir_all(&ca_dir).with_context(|| format!("creating {}", ca_dir.display()))?;
    let ca_key = ec_key()?;
    let ca_cert = certificate(&name("cortex test CA")?, &ca_key, None, (-1, days), true)?;
    let ca = Authority { key: ca_key, cert: ca_cert };
    write(&ca_dir.join("ca.key.pem"), &ca.key.private_key_to_pem_pkcs8()?)?;
    write(&ca_dir.join("ca.cert.pem"), &ca.cert.to_pem()?)?;
    let governance_xml = governance(args.protection);
    let governance_signed = smime_signed(&ca, &governance_xml)?;
    write(&ca_dir.join("governance.xml"), governance_xml.as_bytes())?;
    write(&ca_dir.join("governance.p7s"), &governance_signed)?;
    let topics = if args.topic_prefix == "*" { "*".to_string() } else { format!("{}_*", args.topic_prefix) };
    for (name, may_publish) in names {
        let lifetime = if args.expired.contains(name) { (-2, -1) } else { (-1, days) };
        let dir = args.dir.join(name);
        std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
        let key = ec_key()?;
        let cert = certificate(&self::name(name)?, &key, Some(&ca), lifetime, false)?;
        let permissions_xml = permissions(name, &topics, may_publish, lifetime)?;
        write(&dir.join("identity_ca.cert.pem"), &ca.cert.to_pem()?)?;
        write(&dir.join("permissions_ca.cert.pem"), &ca.cert.to_pem()?)?;
        write(&dir.join("governance.p7s"), &governance_signed)?;
        write(&dir.join("cert.pem"), &cert.to_pem()?)?;
        write(&dir.join("key.pem"), &key.private_key_to_pem_pkcs8()?)?;
        write(&dir.join("permissions.xml"), permissions_xml.as_bytes())?;
        write(&dir.join("permissions.p7s"), &smime_signed(&ca, &permissions_xml)?)?;
        let role = if may_publish {
            "publish and subscribe".to_owned()
        } else {
            format!("read only (publish on {} alone, subscribe)", requests_topic(&topics))
        };
        let expired = if args.expired.contains(name) { ", EXPIRED" } else { "" };
        made.push(format!("{}: {role} on {topics}{expired}", dir.display()));
    }
    made.push(format!("{}: the CA (identity and permissions), governance ({:?})", ca_dir.display(), args.protection));
    Ok(made)
}

/// A fresh two-participant PKI (`bench-a`, `bench-b`; submessages encrypted) in a new directory under the system's
/// temporary directory, for a protected benchmark: the credentials of its two sides.
///
/// # Errors
/// As [`init`].
pub fn bench_credentials() -> Result<measure::bench::Credentials> {
    let dir = std::env::temp_dir().join(format!("cortex-bench-pki-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let args = InitArgs {
        dir: dir.clone(),
        agents: vec!["bench-a".into(), "bench-b".into()],
        readers: Vec::new(),
        expired: Vec::new(),
        topic_prefix: "*".into(),
        protection: Protection::Encrypt,
        days: 2,
    };
    init(&args)?;
    Ok(measure::bench::Credentials { this: dir.join("bench-a"), helper: dir.join("bench-b") })
}

/// Checks the credentials in `dir` as an agent does before it joins: every file present, the identity
/// certificate signed by the identity CA and valid now, the permissions document's grant valid now. Returns a
/// one-line summary (subject and expiry).
///
/// # Errors
/// What is missing, unreadable, not signed by the CA, expired or not yet valid, naming the file.
pub fn check_credentials(dir: &Path) -> Result<String> {
    for file in transport::rtps::SecurityFiles::FILES {
        let path = dir.join(file);
        if !path.is_file() {
            bail!("DDS Security credentials in {}: {file} is missing", dir.display());
        }
    }
    let read = |file: &str| {
        let path = dir.join(file);
        std::fs::read(&path).with_context(|| format!("reading {}", path.display()))
    };
    let pem = |file: &str| -> Result<X509> {
        X509::from_pem(&read(file)?).with_context(|| format!("{}: not a PEM certificate", dir.join(file).display()))
    };
    let (cert, ca) = (pem("cert.pem")?, pem("identity_ca.cert.pem")?);
    PKey::private_key_from_pem(&read("key.pem")?)
        .with_context(|| format!("{}: not an unencrypted PEM private key", dir.join("key.pem").display()))?;
    let ca_key = ca.public_key()?;
    let signed_by_ca = cert.verify(&ca_key).unwrap_or(false);
    if !signed_by_ca {
        bail!(
            "{}: the identity certificate is not signed by the identity CA in {}",
            dir.join("cert.pem").display(),
            dir.join("identity_ca.cert.pem").display()
        );
    }
    let now = Asn1Time::days_from_now(0)?;
    for (what, certificate) in [("cert.pem", &cert), ("identity_ca.cert.pem", &ca)] {
        if certificate.not_after() < now {
            bail!("{}: the certificate expired on {}", dir.join(what).display(), certificate.not_after());
        }
        if certificate.not_before() > now {
            bail!("{}: the certificate is valid only from {}", dir.join(what).display(), certificate.not_before());
        }
    }
    let permissions = String::from_utf8_lossy(&read("permissions.p7s")?).into_owned();
    let not_after = between(&permissions, "<not_after>", "</not_after>");
    let now_text = utc_text(std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH)?.as_secs() as i64);
    if let Some(end) = not_after
        && end.len() >= 19
        && end[..19] < *now_text.as_str()
    {
        bail!("{}: the permissions grant expired on {end}", dir.join("permissions.p7s").display());
    }
    let subject = cert
        .subject_name()
        .entries_by_nid(Nid::COMMONNAME)
        .next()
        .map(|entry| String::from_utf8_lossy(entry.data().as_slice()).into_owned())
        .unwrap_or_default();
    Ok(format!("identity {subject}, certificate valid until {}", cert.not_after()))
}

/// The requests topic among `topics` (`*` or `PREFIX_*`): what a reader may publish.
fn requests_topic(topics: &str) -> String {
    let prefix = topics.strip_suffix('*').unwrap_or(topics);
    format!("{prefix}{}", if prefix.is_empty() { "*_requests" } else { "requests" })
}

/// Whether the permissions in `dir` (`permissions.p7s`, the clear-signed XML) let the participant publish on the
/// updates topic of the graph with topic prefix `topic_prefix` — that is, write the graph. `false` for a reader of
/// `cortex security init --readers`, which may publish requests alone: it can join only read-only.
///
/// # Errors
/// An unreadable permissions file, or one with no grant in it.
pub fn may_write_graph(dir: &Path, topic_prefix: &str) -> Result<bool> {
    let path = dir.join("permissions.p7s");
    let text = std::fs::read(&path).with_context(|| format!("reading {}", path.display()))?;
    let text = String::from_utf8_lossy(&text);
    if !text.contains("<grant") {
        bail!("{}: no permissions grant found", path.display());
    }
    let updates = format!("{topic_prefix}_{}", transport::Channel::Updates.name());
    let mut rest = text.as_ref();
    while let Some(section) = between(rest, "<publish>", "</publish>") {
        let mut topics = section;
        while let Some(topic) = between(topics, "<topic>", "</topic>") {
            if glob_matches(topic, &updates) {
                return Ok(true);
            }
            topics = &topics[topics.find("</topic>").map_or(topics.len(), |at| at + "</topic>".len())..];
        }
        rest = &rest[rest.find("</publish>").map_or(rest.len(), |at| at + "</publish>".len())..];
    }
    Ok(false)
}

/// Whether `name` matches the DDS topic expression `pattern` (`*` any run of characters, `?` one; as `fnmatch`).
fn glob_matches(pattern: &str, name: &str) -> bool {
    let (pattern, name) = (pattern.as_bytes(), name.as_bytes());
    let (mut p, mut n) = (0, 0);
    let mut star: Option<(usize, usize)> = None;
    while n < name.len() {
        if p < pattern.len() && (pattern[p] == b'?' || pattern[p] == name[n]) {
            p += 1;
            n += 1;
        } else if p < pattern.len() && pattern[p] == b'*' {
            star = Some((p, n));
            p += 1;
        } else if let Some((star_p, star_n)) = star {
            p = star_p + 1;
            n = star_n + 1;
            star = Some((star_p, star_n + 1));
        } else {
            return false;
        }
    }
    pattern[p..].iter().all(|&c| c == b'*')
}

fn between<'t>(text: &'t str, start: &str, end: &str) -> Option<&'t str> {
    let from = text.find(start)? + start.len();
    let to = text[from..].find(end)? + from;
    Some(text[from..to].trim())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn topic_expressions_match_as_fnmatch_does() {
        assert!(glob_matches("*", "dsr_updates"));
        assert!(glob_matches("dsr_*", "dsr_updates"));
        assert!(glob_matches("*_requests", "dsr_requests"));
        assert!(!glob_matches("*_requests", "dsr_updates"));
        assert!(!glob_matches("dsr_requests", "dsr_requests_be"));
        assert!(glob_matches("d?r_*s", "dsr_updates"));
        assert!(!glob_matches("robot_*", "dsr_updates"));
    }

    #[test]
    fn readers_may_publish_requests_alone_and_writers_may_write_the_graph() {
        let dir = std::env::temp_dir().join(format!("cortex-unit-pki-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        for (prefix, topics) in [("*", "dsr"), ("robot", "robot")] {
            let pki = dir.join(prefix.replace('*', "all"));
            let args = InitArgs {
                dir: pki.clone(),
                agents: vec!["writer".into()],
                readers: vec!["reader".into()],
                expired: Vec::new(),
                topic_prefix: prefix.into(),
                protection: Protection::Sign,
                days: 2,
            };
            init(&args).unwrap();
            assert!(may_write_graph(&pki.join("writer"), topics).unwrap());
            assert!(!may_write_graph(&pki.join("reader"), topics).unwrap());
            let xml = std::fs::read_to_string(pki.join("reader/permissions.xml")).unwrap();
            let requests = if prefix == "*" { "*_requests" } else { "robot_requests" };
            assert!(xml.contains(&format!("<publish><topics><topic>{requests}</topic>")), "{xml}");
        }
        assert!(may_write_graph(&dir.join("nowhere"), "dsr").unwrap_err().to_string().contains("permissions.p7s"));
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn utc_text_formats_known_instants() {
        assert_eq!(utc_text(0), "1970-01-01T00:00:00");
        assert_eq!(utc_text(951_782_400), "2000-02-29T00:00:00");
        assert_eq!(utc_text(1_700_000_000), "2023-11-14T22:13:20");
    }
}
