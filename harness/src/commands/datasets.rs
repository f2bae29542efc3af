//! `cortex datasets verify`: check the bundled logs against their manifest.
//!
//! `datasets/logs/manifest.json` lists every log with its size and SHA-256 (and its source, licence and topics), and
//! under `containers` every file of the same logs in other containers (with the container and encoding).
//! `verify` hashes each file and reports, per file, `ok`, a size or checksum mismatch, or a missing file; any
//! failure makes the command fail (exit code 1), so CI notices a damaged or replaced log.

use std::fmt::Write as _;
use std::io::Read as _;
use std::path::{Path, PathBuf};

use anyhow::{Context as _, bail};
use clap::{Args, Subcommand};
use serde::{Deserialize, Serialize};
use sha2::{Digest as _, Sha256};

/// Arguments of `cortex datasets`.
#[derive(Debug, Args)]
pub struct DatasetsArgs {
    /// What to do.
    #[command(subcommand)]
    command: DatasetsCommand,
}

/// The `cortex datasets` subcommands.
#[derive(Debug, Subcommand)]
enum DatasetsCommand {
    /// Check size and SHA-256 of every file the manifest lists.
    Verify {
        /// The folder holding `manifest.json` (default: `datasets/logs` of the repository).
        #[arg(long)]
        dir: Option<PathBuf>,
        /// Print stable, machine-readable JSON instead of text.
        #[arg(long)]
        json: bool,
    },
}

#[derive(Debug, Deserialize)]
struct Manifest {
    files: Vec<Entry>,
    /// The same logs in other containers (`containers/…`: ROS 1 bags, ROS 1 MCAP, rosbag2 directories' files).
    #[serde(default)]
    containers: Vec<Entry>,
}

#[derive(Debug, Deserialize)]
struct Entry {
    file: String,
    bytes: u64,
    sha256: String,
    licence: String,
}

#[derive(Debug, Serialize)]
struct Check {
    file: String,
    licence: String,
    ok: bool,
    problem: Option<String>,
}

/// Runs a `cortex datasets` subcommand.
///
/// # Errors
/// An unreadable manifest, or any file missing, of the wrong size or with the wrong checksum.
pub fn run(args: DatasetsArgs) -> anyhow::Result<()> {
    let DatasetsCommand::Verify { dir, json } = args.command;
    let dir = dir.unwrap_or_else(default_dir);
    let manifest_path = dir.join("manifest.json");
    let text = std::fs::read_to_string(&manifest_path)
        .with_context(|| format!("cannot read the manifest {}", manifest_path.display()))?;
    let manifest: Manifest =
        serde_json::from_str(&text).with_context(|| format!("{}: not a valid manifest", manifest_path.display()))?;
    let checks: Vec<Check> =
        manifest.files.iter().chain(&manifest.containers).map(|entry| check(&dir, entry)).collect();
    let failed = checks.iter().filter(|check| !check.ok).count();
    if json {
        println!("{}", serde_json::to_string_pretty(&serde_json::json!({ "dir": dir, "files": checks }))?);
    } else {
        let mut out = String::new();
        for check in &checks {
            let verdict = check.problem.as_deref().unwrap_or("ok");
            let _ = writeln!(out, "{:<52} {verdict}", check.file);
        }
        let _ = writeln!(out, "{} of {} files ok ({})", checks.len() - failed, checks.len(), manifest_path.display());
        print!("{out}");
    }
    if failed > 0 {
        bail!("{failed} of {} files in {} do not match the manifest", checks.len(), dir.display());
    }
    Ok(())
}

/// `datasets/logs` of the current directory if it is there, else of the repository this binary was built from.
fn default_dir() -> PathBuf {
    let here = PathBuf::from("datasets/logs");
    if here.join("manifest.json").is_file() {
        return here;
    }
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../datasets/logs")
}

fn check(dir: &Path, entry: &Entry) -> Check {
    let problem = match hash(&dir.join(&entry.file)) {
        Err(error) => Some(format!("MISSING or unreadable: {error}")),
        Ok((bytes, _)) if bytes != entry.bytes => {
            Some(format!("SIZE MISMATCH: {bytes} bytes, manifest says {}", entry.bytes))
        }
        Ok((_, sha256)) if !sha256.eq_ignore_ascii_case(&entry.sha256) => {
            Some(format!("CHECKSUM MISMATCH: sha256 {sha256}, manifest says {}", entry.sha256))
        }
        Ok(_) => None,
    };
    Check { file: entry.file.clone(), licence: entry.licence.clone(), ok: problem.is_none(), problem }
}

fn hash(path: &Path) -> std::io::Result<(u64, String)> {
    let mut file = std::fs::File::open(path)?;
    let mut hasher = Sha256::new();
    let mut buffer = vec![0u8; 1 << 16];
    let mut total = 0u64;
    loop {
        let n = file.read(&mut buffer)?;
        if n == 0 {
            break;
        }
        total += n as u64;
        hasher.update(&buffer[..n]);
    }
    let digest = hasher.finalize();
    Ok((
        total,
        digest.iter().fold(String::new(), |mut hex, byte| {
            let _ = write!(hex, "{byte:02x}");
            hex
        }),
    ))
}
