//! `cortex security init DIR`: a small test PKI for DDS Security (issue 22), in the layout of ROS 2 security
//! enclaves, which `cortex agent --security DIR/NAME` and `cortex inspect --security DIR/NAME` read
//! (`transport::rtps::SecurityFiles`); `cortex security revoke DIR NAME...`, revocation by rotating its CA; and
//! `cortex security check DIR/NAME`, the check those commands make before joining.
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
//! - Revocation ([`mod@revoke`]): revocation lists are not offered, since `rustdds` 0.15 does not read them
//!   (`DomainParticipantSecurityConfigFiles::certificate_revocation_list` is "not yet implemented"). Instead the CA
//!   is rotated: a new CA re-signs the governance and re-issues every other participant (same subject, validity and
//!   permissions document), the old CA is kept in `DIR/ca/retired-N/`, and the revoked participants' directories
//!   keep their old credentials with a `REVOKED` marker, recorded in `DIR/revoked.txt`. Peers holding the new CA do
//!   not authenticate the old credentials; running agents must be restarted with their re-issued ones, since DDS
//!   Security authenticates at discovery.
//! - The check ([`check_credentials`], which `cortex agent --security` and `cortex inspect --security` run before
//!   joining) refuses a `REVOKED` directory, missing or unreadable files, a certificate not signed by its CA, a CA
//!   other than the PKI's current one (`DIR/ca/ca.cert.pem` beside the participant's directory, when it is there),
//!   and an expired or not yet valid certificate or grant.
//!
//! All the cryptography is the `openssl` crate's (the OpenSSL that `rustdds`'s `security` feature links): keys,
//! certificates, S/MIME signatures (`pki.rs`, shared by `init` and `revoke`).

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use clap::{Args, Subcommand, ValueEnum};
use openssl::asn1::Asn1Time;
use openssl::nid::Nid;
use openssl::pkey::PKey;
use openssl::x509::X509;

mod pki;
mod revoke;

pub use revoke::{RevokeArgs, revoke};

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
    /// Revoke participants by rotating the CA: a new CA re-issues every other participant's credentials (same
    /// grants) and re-signs the governance; the revoked keep their old credentials, marked `REVOKED`.
    Revoke(RevokeArgs),
    /// Check a participant's credentials as an agent would before joining (not revoked, files present, signed by
    /// the PKI's current CA, certificate and grant valid now).
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
        SecurityCommand::Revoke(args) => {
            for line in revoke(&args)? {
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

fn valid_name(name: &str) -> bool {
    !name.is_empty() && name != "ca" && name.bytes().all(|b| b.is_ascii_alphanumeric() || b == b'-' || b == b'_')
}

/// Creates the PKI `args` describe; returns one line per directory made (what it may do).
///
/// # Errors
/// A bad participant name or topic prefix, an existing PKI (or revocation record) in the directory, or a file that
/// cannot be written.
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
    let registry = args.dir.join(revoke::REGISTRY);
    if registry.exists() {
        bail!(
            "{} records revoked participants of an earlier PKI; choose another directory (or `cortex security revoke` \
             in the existing one)",
            registry.display()
        );
    }
    if !(args.topic_prefix == "*" || valid_name(&args.topic_prefix)) {
        bail!("--topic-prefix {:?}: use letters, digits, '-' and '_', or *", args.topic_prefix);
    }
    let days = i64::from(args.days.max(1));
    let ca_dir = args.dir.join("ca");
    let ca = pki::Authority::new(days)?;
    let governance_xml = pki::governance(args.protection);
    let governance_signed = pki::smime_signed(&ca, &governance_xml)?;
    let mut ca_files = ca.files()?;
    ca_files.push(("governance.xml", governance_xml.into_bytes()));
    ca_files.push(("governance.p7s", governance_signed.clone()));
    let topics = if args.topic_prefix == "*" { "*".to_string() } else { format!("{}_*", args.topic_prefix) };
    let mut participants = Vec::new();
    for (name, may_publish) in names {
        let lifetime = if args.expired.contains(name) { (-2, -1) } else { (-1, days) };
        let (not_before, not_after) = pki::validity(lifetime)?;
        let permissions_xml = pki::permissions(name, &topics, may_publish, lifetime)?;
        let files = pki::credentials(&ca, &governance_signed, name, (&not_before, &not_after), &permissions_xml)?;
        participants.push((args.dir.join(name), files));
        let role = if may_publish {
            "publish and subscribe".to_owned()
        } else {
            format!("read only (publish on {} alone, subscribe)", requests_topic(&topics))
        };
        let expired = if args.expired.contains(name) { ", EXPIRED" } else { "" };
        made.push(format!("{}: {role} on {topics}{expired}", args.dir.join(name).display()));
    }
    pki::write_files(&ca_dir, &ca_files)?;
    for (dir, files) in &participants {
        pki::write_files(dir, files)?;
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

/// Checks the credentials in `dir` as an agent does before it joins: not revoked (no `REVOKED` marker of
/// `cortex security revoke`), every file present, the identity certificate signed by the identity CA and valid now,
/// the CA the PKI's current one when the PKI's `ca/` is beside `dir`, the permissions document's grant valid now.
/// Returns a one-line summary (subject and expiry).
///
/// # Errors
/// Revoked credentials (naming the marker and its date), or what is missing, unreadable, not signed by the current
/// CA, expired or not yet valid, naming the file.
pub fn check_credentials(dir: &Path) -> Result<String> {
    revoke::check_not_revoked(dir)?;
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
    revoke::check_current_ca(dir)?;
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
    let now_text = pki::utc_text(pki::now_unix()?);
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
/// As the builtin access control decides: the first `allow_rule` or `deny_rule` of the grant whose `publish`
/// topic expressions (fnmatch patterns) match the topic decides, else the grant's `default`. Domain ranges are not
/// read (`cortex security init` grants every domain).
///
/// # Errors
/// An unreadable permissions file, or one with no grant in it, or XML that does not parse.
pub fn may_write_graph(dir: &Path, topic_prefix: &str) -> Result<bool> {
    let path = dir.join("permissions.p7s");
    let bytes = std::fs::read(&path).with_context(|| format!("reading {}", path.display()))?;
    let text = String::from_utf8_lossy(&bytes);
    // The clear-signed S/MIME message carries the document verbatim between its MIME headers and the signature.
    let xml = text
        .find("<dds")
        .zip(text.rfind("</dds>"))
        .map(|(from, to)| &text[from..to + "</dds>".len()])
        .with_context(|| format!("{}: no permissions document (<dds>...</dds>) found", path.display()))?;
    let updates = format!("{topic_prefix}_{}", transport::Channel::Updates.name());
    let grant = publish_rules(xml).with_context(|| format!("reading the permissions in {}", path.display()))?;
    let Some(grant) = grant else { bail!("{}: no permissions grant found", path.display()) };
    let matches = |pattern: &str| glob::Pattern::new(pattern).is_ok_and(|p| p.matches(&updates));
    let decided = grant.rules.iter().find(|(_, topics)| topics.iter().any(|t| matches(t)));
    Ok(decided.map_or(grant.default_allows, |(allows, _)| *allows))
}

/// A grant's publish rules, in order: whether each allows, and its topic expressions; and its default.
struct PublishGrant {
    rules: Vec<(bool, Vec<String>)>,
    default_allows: bool,
}

/// The publish rules of the first grant in `xml`, or `None` without a grant.
fn publish_rules(xml: &str) -> Result<Option<PublishGrant>> {
    use quick_xml::events::Event;
    let mut reader = quick_xml::Reader::from_str(xml);
    reader.config_mut().trim_text(true);
    let mut path: Vec<String> = Vec::new();
    let mut grant: Option<PublishGrant> = None;
    loop {
        let position = reader.buffer_position();
        match reader.read_event().with_context(|| format!("XML at byte {position}"))? {
            Event::Start(start) => {
                let name = start.local_name().into_inner().to_owned();
                match name.as_str() {
                    "grant" if grant.is_none() => {
                        grant = Some(PublishGrant { rules: Vec::new(), default_allows: false })
                    }
                    "allow_rule" | "deny_rule" if directly_under_grant(&path) => {
                        if let Some(grant) = grant.as_mut() {
                            grant.rules.push((name == "allow_rule", Vec::new()));
                        }
                    }
                    _ => {}
                }
                path.push(name);
            }
            Event::End(_) => {
                let closed = path.pop();
                if closed.as_deref() == Some("grant") {
                    break; // The first grant is the participant's.
                }
            }
            Event::Text(text) => {
                let text = text.xml10_content().trim().to_owned();
                let names: Vec<&str> = path.iter().map(String::as_str).collect();
                match (grant.as_mut(), names.as_slice()) {
                    (Some(grant), [.., "grant", _, "publish", "topics", "topic"]) => {
                        if let Some((_, topics)) = grant.rules.last_mut() {
                            topics.push(text);
                        }
                    }
                    (Some(grant), [.., "grant", "default"]) => grant.default_allows = text == "ALLOW",
                    _ => {}
                }
            }
            Event::Eof => break,
            _ => {}
        }
    }
    Ok(grant)
}

/// Whether an element opened under `path` is a direct child of a grant.
fn directly_under_grant(path: &[String]) -> bool {
    path.last().is_some_and(|last| last == "grant")
}

/// The trimmed text between the first `start` and the next `end` in `text`.
fn between<'t>(text: &'t str, start: &str, end: &str) -> Option<&'t str> {
    let from = text.find(start)? + start.len();
    let to = text[from..].find(end)? + from;
    Some(text[from..to].trim())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A grant with `rules` (`(allow, publish topic expressions)`) and `default`, in a permissions document.
    fn document(rules: &[(bool, &[&str])], default: &str) -> String {
        let rules: String = rules
            .iter()
            .map(|(allow, topics)| {
                let kind = if *allow { "allow_rule" } else { "deny_rule" };
                let topics: String = topics.iter().map(|t| format!("<topic>{t}</topic>")).collect();
                format!("<{kind}><domains><id>0</id></domains><publish><topics>{topics}</topics></publish></{kind}>")
            })
            .collect();
        format!(
            "<dds><permissions><grant name=\"g\"><subject_name>CN=g</subject_name>{rules}<default>{default}</default></grant></permissions></dds>"
        )
    }

    fn decides(rules: &[(bool, &[&str])], default: &str) -> bool {
        let dir = std::env::temp_dir().join(format!("cortex-unit-grant-rules-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(dir.join("permissions.p7s"), format!("MIME-Version: 1.0\n\n{}\n", document(rules, default)))
            .unwrap();
        let decided = may_write_graph(&dir, "dsr").unwrap();
        let _ = std::fs::remove_dir_all(&dir);
        decided
    }

    #[test]
    fn the_first_rule_whose_topic_expression_matches_the_updates_topic_decides_else_the_default() {
        assert!(decides(&[(true, &["*"])], "DENY"));
        assert!(decides(&[(true, &["d?r_*s"])], "DENY"), "fnmatch's ? and *");
        assert!(!decides(&[(true, &["*_requests"])], "DENY"), "a reader's grant");
        assert!(!decides(&[(true, &["dsr_updates_be"])], "DENY"));
        assert!(!decides(&[(false, &["dsr_*"]), (true, &["*"])], "ALLOW"), "a deny rule first");
        assert!(decides(&[(true, &["dsr_[tu]pdates"]), (false, &["*"])], "DENY"), "an allow rule first, with a class");
        assert!(decides(&[(true, &["robot_*"])], "ALLOW"), "no rule matches: the default");
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
}
