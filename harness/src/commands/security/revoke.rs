//! `cortex security revoke DIR NAME...`: revocation by rotating the CA (issue 22).
//!
//! `rustdds` 0.15 reads no certificate revocation list, so a peer's certificate cannot be refused by one. What small
//! DDS Security deployments do instead: a new CA. `revoke` makes a new CA key and self-signed certificate in
//! `DIR/ca/` (the old key, certificate and signed governance move to `DIR/ca/retired-N/`), re-signs the governance
//! (`DIR/ca/governance.xml`, unchanged) and re-issues every other participant's credentials — a fresh key, an identity
//! certificate with the same subject and validity, the same permissions document (read from the `permissions.xml`
//! beside `permissions.p7s`, else from the signed copy) signed by the new CA. The revoked participants' directories
//! keep their old credentials and get a `REVOKED` marker (when, by which command), and `DIR/revoked.txt` records
//! them, so a later `revoke` refuses them and `init` will not reuse the directory.
//!
//! The enforcement is by the peers: agents holding the new CA do not authenticate a participant whose identity the
//! retired CA signed, so it neither reads nor writes their graph. Running agents keep the sessions they
//! authenticated at discovery: they must be restarted with their re-issued credentials. Locally,
//! [`check_not_revoked`] and [`check_current_ca`] (part of `super::check_credentials`, which `cortex agent` and
//! `cortex inspect` run before joining) refuse a marked directory and credentials of a retired CA.

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use clap::Args;
use openssl::x509::X509;

use super::pki;

/// The file in the PKI's directory recording the revoked participants, one line each (name, date, retired CA).
pub(super) const REGISTRY: &str = "revoked.txt";
/// The marker file `revoke` leaves in a revoked participant's directory.
pub(super) const MARKER: &str = "REVOKED";
/// The signed governance, in `DIR/ca/` and in every participant's directory.
const GOVERNANCE_SIGNED: &str = "governance.p7s";

/// Arguments of `cortex security revoke`.
#[derive(Debug, Args)]
pub struct RevokeArgs {
    /// The PKI's directory (made by `cortex security init`).
    pub dir: PathBuf,
    /// The participants to revoke (their directories' names in the PKI).
    #[arg(required = true)]
    pub names: Vec<String>,
    /// Validity of the new CA, days (re-issued certificates and grants keep their own validity).
    #[arg(long, default_value_t = 365)]
    pub days: u32,
}

/// The revoked participants `DIR/revoked.txt` records: each name with the rest of its line.
fn registry(dir: &Path) -> Result<Vec<(String, String)>> {
    let path = dir.join(REGISTRY);
    if !path.exists() {
        return Ok(Vec::new());
    }
    let text = std::fs::read_to_string(&path).with_context(|| format!("reading {}", path.display()))?;
    Ok(text
        .lines()
        .map(str::trim)
        .filter(|line| !line.is_empty() && !line.starts_with('#'))
        .map(|line| {
            let (name, rest) = line.split_once(char::is_whitespace).unwrap_or((line, ""));
            (name.to_owned(), rest.trim().replace('\t', ", "))
        })
        .collect())
}

/// The participants of the PKI in `dir`: its subdirectories (other than `ca`) holding a `cert.pem`, by name.
fn participants(dir: &Path) -> Result<Vec<String>> {
    let mut names = Vec::new();
    for entry in std::fs::read_dir(dir).with_context(|| format!("reading {}", dir.display()))? {
        let entry = entry.with_context(|| format!("reading {}", dir.display()))?;
        let Ok(name) = entry.file_name().into_string() else { continue };
        if super::valid_name(&name) && entry.path().join("cert.pem").is_file() {
            names.push(name);
        }
    }
    names.sort();
    Ok(names)
}

/// The permissions document (XML) of participant `name` in `dir`: `permissions.xml`, else the document inside the
/// clear-signed `permissions.p7s`. It must grant the participant's own subject.
fn grant(dir: &Path, name: &str) -> Result<String> {
    let xml = dir.join("permissions.xml");
    let (path, text) = if xml.is_file() {
        (xml.clone(), std::fs::read_to_string(&xml).with_context(|| format!("reading {}", xml.display()))?)
    } else {
        let signed = dir.join("permissions.p7s");
        let bytes = std::fs::read(&signed).with_context(|| format!("reading {}", signed.display()))?;
        let text = String::from_utf8_lossy(&bytes).replace("\r\n", "\n");
        let document = text
            .find("<?xml")
            .and_then(|from| text[from..].find("</dds>").map(|to| text[from..from + to].to_owned() + "</dds>\n"));
        let Some(document) = document else {
            bail!("{}: no permissions document found to re-issue", signed.display());
        };
        (signed, document)
    };
    let subject = pki::subject(name);
    if !text.contains("<grant") || !text.contains(&format!("<subject_name>{subject}</subject_name>")) {
        bail!("{}: no grant for {subject} found; it cannot be re-issued as it was", path.display());
    }
    Ok(text)
}

/// What a grant lets its participant publish and subscribe, for printing.
fn role(grant: &str) -> String {
    let topics = |section: &str| {
        super::between(grant, &format!("<{section}>"), &format!("</{section}>"))
            .and_then(|inner| super::between(inner, "<topic>", "</topic>"))
            .unwrap_or("nothing")
            .to_owned()
    };
    format!("publish {}, subscribe {}", topics("publish"), topics("subscribe"))
}

/// Revokes the participants `args` names by rotating the PKI's CA (see the module doc); returns what it did, one
/// line each, ending with the reminder that running agents must be restarted.
///
/// # Errors
/// No PKI in the directory, an unknown or already revoked participant (or one named twice), credentials that cannot
/// be read to be re-issued, or a file that cannot be written. Nothing is written unless every participant's new
/// credentials were made.
pub fn revoke(args: &RevokeArgs) -> Result<Vec<String>> {
    let dir = &args.dir;
    let ca_dir = dir.join("ca");
    if !ca_dir.join(pki::CA_CERT).is_file() {
        bail!("{}: no PKI of `cortex security init` here (ca/{} is missing)", dir.display(), pki::CA_CERT);
    }
    let governance_path = ca_dir.join("governance.xml");
    let governance_xml = std::fs::read_to_string(&governance_path)
        .with_context(|| format!("reading {} (the governance to re-sign)", governance_path.display()))?;
    let recorded = registry(dir)?;
    let known = participants(dir)?;
    let mut revoking: Vec<&str> = Vec::new();
    for name in &args.names {
        if !super::valid_name(name) {
            bail!("participant name {name:?}: use letters, digits, '-' and '_' (and not \"ca\")");
        }
        if revoking.contains(&name.as_str()) {
            bail!("{name} is named twice");
        }
        if let Some((_, when)) = recorded.iter().find(|(n, _)| n == name) {
            bail!("{name} was already revoked ({when}; {})", dir.join(REGISTRY).display());
        }
        let marker = dir.join(name).join(MARKER);
        if marker.exists() {
            bail!("{name} was already revoked ({} is there)", marker.display());
        }
        if !known.contains(name) {
            let others = known.iter().filter(|n| !recorded.iter().any(|(r, _)| r == *n)).cloned().collect::<Vec<_>>();
            bail!("no participant {name:?} in {} (its participants: {})", dir.display(), others.join(", "));
        }
        revoking.push(name);
    }
    let keep: Vec<&String> = known
        .iter()
        .filter(|n| !revoking.contains(&n.as_str()))
        .filter(|n| !recorded.iter().any(|(r, _)| r == *n) && !dir.join(n).join(MARKER).exists())
        .collect();

    // Everything new is made in memory first.
    let ca = pki::Authority::new(i64::from(args.days.max(1)))?;
    let governance_signed = pki::smime_signed(&ca, &governance_xml)?;
    let mut reissued = Vec::new();
    for name in &keep {
        let participant = dir.join(name);
        let cert_path = participant.join("cert.pem");
        let cert =
            std::fs::read(&cert_path).with_context(|| format!("reading {}", cert_path.display())).and_then(|pem| {
                X509::from_pem(&pem).with_context(|| format!("{}: not a PEM certificate", cert_path.display()))
            })?;
        let grant = grant(&participant, name)?;
        let files = pki::credentials(&ca, &governance_signed, name, (cert.not_before(), cert.not_after()), &grant)?;
        reissued.push((participant, role(&grant), files));
    }

    // Then the old CA is retired and the new files written.
    let retired = (1..).map(|n| ca_dir.join(format!("retired-{n}"))).find(|path| !path.exists()).unwrap_or_default();
    std::fs::create_dir_all(&retired).with_context(|| format!("creating {}", retired.display()))?;
    for file in [pki::CA_KEY, pki::CA_CERT, GOVERNANCE_SIGNED] {
        let (from, to) = (ca_dir.join(file), retired.join(file));
        if from.exists() {
            std::fs::rename(&from, &to).with_context(|| format!("moving {} to {}", from.display(), to.display()))?;
        }
    }
    let mut ca_files = ca.files()?;
    ca_files.push((GOVERNANCE_SIGNED, governance_signed));
    pki::write_files(&ca_dir, &ca_files)?;
    let mut done = vec![format!(
        "{}: a new CA, governance re-signed; the old CA (key, certificate, signed governance) retired to {}",
        ca_dir.display(),
        retired.display()
    )];
    for (participant, role, files) in &reissued {
        pki::write_files(participant, files)?;
        done.push(format!("{}: re-issued by the new CA (same grant: {role})", participant.display()));
    }
    let when = format!("{} UTC", pki::utc_text(pki::now_unix()?));
    let retired_name = retired.strip_prefix(dir).unwrap_or(&retired).display().to_string();
    let registry_path = dir.join(REGISTRY);
    let mut record = if registry_path.exists() {
        std::fs::read_to_string(&registry_path).with_context(|| format!("reading {}", registry_path.display()))?
    } else {
        "# Participants revoked by `cortex security revoke`: name, when, the CA that signed their credentials.\n"
            .to_owned()
    };
    for name in &revoking {
        let marker = dir.join(name).join(MARKER);
        let text = format!(
            "revoked {when} by `cortex security revoke`: the CA that signed these credentials was retired to \
             {retired_name}, and agents holding the PKI's new CA refuse them\n"
        );
        pki::write(&marker, text.as_bytes())?;
        record.push_str(&format!("{name}\t{when}\t{retired_name}\n"));
        done.push(format!(
            "{}: REVOKED (old credentials left, marked by {})",
            dir.join(name).display(),
            marker.display()
        ));
    }
    pki::write(&registry_path, record.as_bytes())?;
    done.push(format!("{}: records the revoked participants", registry_path.display()));
    done.push(
        "Restart every running agent and inspector with its re-issued credentials: DDS Security authenticates \
         peers at discovery, so running processes keep their old sessions (the revoked participant's included) \
         until they restart."
            .to_owned(),
    );
    Ok(done)
}

/// Refuses credentials in `dir` that `cortex security revoke` marked revoked.
///
/// # Errors
/// The marker is there: the error names it and quotes its first line (when and by which command).
pub(super) fn check_not_revoked(dir: &Path) -> Result<()> {
    let marker = dir.join(MARKER);
    if marker.exists() {
        let text = std::fs::read(&marker).map(|bytes| String::from_utf8_lossy(&bytes).into_owned()).unwrap_or_default();
        let said = text.lines().next().map(str::trim).filter(|line| !line.is_empty()).unwrap_or("revoked");
        bail!("{}: these credentials were {said}", marker.display());
    }
    Ok(())
}

/// Refuses credentials in `dir` whose identity or permissions CA is not the current CA of the PKI they sit in
/// (`dir/../ca/ca.cert.pem`), when that file is there and readable: credentials of a CA that `revoke` retired.
///
/// # Errors
/// A CA certificate that differs from the PKI's current one (naming both files), or one that cannot be read.
pub(super) fn check_current_ca(dir: &Path) -> Result<()> {
    let Some(pki_dir) = dir.parent() else { return Ok(()) };
    let current_path = pki_dir.join("ca").join(pki::CA_CERT);
    let Ok(current) = std::fs::read(&current_path) else { return Ok(()) };
    let Ok(current) = X509::from_pem(&current) else { return Ok(()) };
    let current = current.to_der()?;
    for file in ["identity_ca.cert.pem", "permissions_ca.cert.pem"] {
        let path = dir.join(file);
        let bytes = std::fs::read(&path).with_context(|| format!("reading {}", path.display()))?;
        let ca = X509::from_pem(&bytes).with_context(|| format!("{}: not a PEM certificate", path.display()))?;
        if ca.to_der()? != current {
            bail!(
                "{}: not the PKI's current CA ({}); the CA was rotated (`cortex security revoke`), so agents \
                 holding the current CA refuse these credentials",
                path.display(),
                current_path.display()
            );
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::super::{InitArgs, Protection, check_credentials, init, may_write_graph};
    use super::*;

    fn revoke_in(dir: &Path, names: &[&str]) -> Result<Vec<String>> {
        revoke(&RevokeArgs { dir: dir.to_path_buf(), names: names.iter().map(|n| n.to_string()).collect(), days: 2 })
    }

    #[test]
    fn revoking_rotates_the_ca_reissues_the_others_and_marks_the_revoked() {
        let dir = std::env::temp_dir().join(format!("cortex-unit-revoke-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let args = InitArgs {
            dir: dir.clone(),
            agents: vec!["a1".into(), "a2".into(), "a3".into()],
            readers: vec!["reader".into()],
            expired: Vec::new(),
            topic_prefix: "robot".into(),
            protection: Protection::Sign,
            days: 2,
        };
        init(&args).unwrap();
        let read = |path: &str| std::fs::read(dir.join(path)).unwrap();
        let files = |name: &str| -> Vec<(std::ffi::OsString, Vec<u8>)> {
            let entries = std::fs::read_dir(dir.join(name)).unwrap();
            entries.map(|e| e.unwrap()).map(|e| (e.file_name(), std::fs::read(e.path()).unwrap())).collect()
        };
        let put = |name: &str, files: &[(std::ffi::OsString, Vec<u8>)]| {
            for (file, bytes) in files {
                std::fs::write(dir.join(name).join(file), bytes).unwrap();
            }
        };
        let (old_ca, old_a1) = (read("ca/ca.cert.pem"), files("a1"));
        let old_grant = read("reader/permissions.xml");

        let done = revoke_in(&dir, &["a3"]).unwrap();
        assert!(done.last().unwrap().contains("Restart"), "{done:?}");
        assert_eq!(read("ca/retired-1/ca.cert.pem"), old_ca);
        assert_ne!(read("ca/ca.cert.pem"), old_ca);
        for name in ["a1", "a2", "reader"] {
            assert_eq!(read(&format!("{name}/identity_ca.cert.pem")), read("ca/ca.cert.pem"));
            check_credentials(&dir.join(name)).unwrap();
        }
        // Same grants, same roles.
        assert_eq!(read("reader/permissions.xml"), old_grant);
        assert!(may_write_graph(&dir.join("a1"), "robot").unwrap());
        assert!(!may_write_graph(&dir.join("reader"), "robot").unwrap());
        // The revoked keep their old credentials, refused locally with the marker's date.
        assert_eq!(read("a3/identity_ca.cert.pem"), old_ca);
        let refused = check_credentials(&dir.join("a3")).unwrap_err().to_string();
        assert!(refused.contains("REVOKED") && refused.contains("revoked 20") && refused.contains("UTC"), "{refused}");
        assert!(String::from_utf8(read(REGISTRY)).unwrap().contains("a3\t"));
        // Old credentials put back in a current participant's directory are refused: not the current CA.
        let new_a1 = files("a1");
        put("a1", &old_a1);
        let stale = check_credentials(&dir.join("a1")).unwrap_err().to_string();
        assert!(stale.contains("not the PKI's current CA"), "{stale}");

        // Bad requests are refused with clear errors and change nothing.
        let again = revoke_in(&dir, &["a3"]).unwrap_err().to_string();
        assert!(again.contains("already revoked"), "{again}");
        let unknown = revoke_in(&dir, &["nobody"]).unwrap_err().to_string();
        assert!(unknown.contains("no participant \"nobody\"") && unknown.contains("a1, a2, reader"), "{unknown}");
        let twice = revoke_in(&dir, &["a2", "a2"]).unwrap_err().to_string();
        assert!(twice.contains("named twice"), "{twice}");
        let bad = revoke_in(&dir, &["../a1"]).unwrap_err().to_string();
        assert!(bad.contains("participant name"), "{bad}");
        assert!(!dir.join("ca/retired-2").exists());
        let nowhere = revoke_in(&dir.join("a1"), &["a2"]).unwrap_err().to_string();
        assert!(nowhere.contains("no PKI"), "{nowhere}");
        let reinit = init(&InitArgs { dir: dir.clone(), ..args }).unwrap_err().to_string();
        assert!(reinit.contains("already holds a PKI"), "{reinit}");

        // A second revocation retires the second CA and skips the first revoked.
        put("a1", &new_a1);
        revoke_in(&dir, &["a2"]).unwrap();
        assert!(dir.join("ca/retired-2/ca.cert.pem").is_file());
        check_credentials(&dir.join("a1")).unwrap();
        assert!(check_credentials(&dir.join("a2")).is_err() && check_credentials(&dir.join("a3")).is_err());
        let record = String::from_utf8(read(REGISTRY)).unwrap();
        assert!(record.contains("a3\t") && record.contains("a2\t") && record.contains("ca/retired-2"), "{record}");
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn a_grant_is_read_from_the_signed_copy_when_the_xml_is_gone() {
        let dir = std::env::temp_dir().join(format!("cortex-unit-grant-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let args = InitArgs {
            dir: dir.clone(),
            agents: vec!["a1".into()],
            readers: Vec::new(),
            expired: Vec::new(),
            topic_prefix: "*".into(),
            protection: Protection::Encrypt,
            days: 2,
        };
        init(&args).unwrap();
        let xml = std::fs::read_to_string(dir.join("a1/permissions.xml")).unwrap();
        std::fs::remove_file(dir.join("a1/permissions.xml")).unwrap();
        assert_eq!(grant(&dir.join("a1"), "a1").unwrap(), xml);
        let wrong = grant(&dir.join("a1"), "a2").unwrap_err().to_string();
        assert!(wrong.contains("no grant for CN=a2,O=cortex"), "{wrong}");
        let _ = std::fs::remove_dir_all(&dir);
    }
}
