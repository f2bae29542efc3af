//! Where a result came from: the commit (and whether the tree had local changes), the compiler, the machine,
//! the command line, the seeds, and the checksums of the datasets used — everything needed to read a number
//! later or to reproduce it. Read at run time (`git`, `rustc`, `/proc`), each field `None`/`"unknown"` when it
//! cannot be read rather than failing the run.

use std::collections::BTreeMap;
use std::path::Path;
use std::process::Command;

use serde::{Deserialize, Serialize};
use sha2::{Digest as _, Sha256};

/// The machine a run measured.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Machine {
    /// Logical CPUs this process may use.
    pub cpus: usize,
    /// CPU model name (`/proc/cpuinfo`).
    pub cpu_model: String,
    /// Total memory in bytes (`/proc/meminfo`).
    pub memory_bytes: Option<u64>,
    /// Kernel release (`/proc/sys/kernel/osrelease`).
    pub kernel: String,
    /// 1-minute load average when the run started (`/proc/loadavg`): how busy the machine was.
    pub load_average_1m: Option<f64>,
}

impl Machine {
    /// The machine this process runs on.
    pub fn current() -> Machine {
        let cpuinfo = std::fs::read_to_string("/proc/cpuinfo").unwrap_or_default();
        let cpu_model = cpuinfo
            .lines()
            .find(|l| l.starts_with("model name"))
            .and_then(|l| l.split(':').nth(1))
            .map_or_else(|| "unknown".to_owned(), |m| m.trim().to_owned());
        let memory_bytes = std::fs::read_to_string("/proc/meminfo").ok().and_then(|text| {
            let line = text.lines().find(|l| l.starts_with("MemTotal:"))?;
            Some(line.split_whitespace().nth(1)?.parse::<u64>().ok()? * 1024)
        });
        let kernel = std::fs::read_to_string("/proc/sys/kernel/osrelease")
            .map_or_else(|_| "unknown".to_owned(), |k| k.trim().to_owned());
        let load_average_1m =
            std::fs::read_to_string("/proc/loadavg").ok().and_then(|text| text.split_whitespace().next()?.parse().ok());
        Machine {
            cpus: std::thread::available_parallelism().map_or(1, usize::from),
            cpu_model,
            memory_bytes,
            kernel,
            load_average_1m,
        }
    }

    /// One line: `2 CPUs (model), 7.8 GiB, Linux 6.x, load 0.5`.
    pub fn summary(&self) -> String {
        let memory = self
            .memory_bytes
            .map_or_else(|| "? GiB".to_owned(), |b| format!("{:.1} GiB", b as f64 / (1u64 << 30) as f64));
        let load = self.load_average_1m.map_or_else(|| "?".to_owned(), |l| format!("{l:.2}"));
        format!("{} CPUs ({}), {memory}, Linux {}, load {load} at start", self.cpus, self.cpu_model, self.kernel)
    }
}

/// A dataset file used by a run, with its checksum computed now and the one its manifest states.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct DatasetChecksum {
    /// Path as given.
    pub file: String,
    /// Size in bytes.
    pub bytes: u64,
    /// SHA-256 of the file as read for this run.
    pub sha256: String,
    /// SHA-256 stated by `manifest.json` beside it, if any.
    pub manifest_sha256: Option<String>,
}

impl DatasetChecksum {
    /// Reads and hashes `path`, and looks it up in the `manifest.json` of its directory or of the directory above
    /// (`datasets/logs/containers/…` is listed in `datasets/logs/manifest.json`). A directory (a rosbag2 bag) is
    /// hashed as the SHA-256 of its files' `NAME SHA256` lines in name order, and compared with the same hash of
    /// the manifest's entries for its files.
    ///
    /// # Errors
    /// The file (or a file of the directory) cannot be read.
    pub fn of(path: &Path) -> std::io::Result<DatasetChecksum> {
        let (bytes, sha256) = if path.is_dir() {
            let mut lines = String::new();
            let mut bytes = 0;
            let mut names: Vec<_> = std::fs::read_dir(path)?.collect::<Result<Vec<_>, _>>()?;
            names.sort_by_key(std::fs::DirEntry::file_name);
            for entry in names.iter().filter(|entry| entry.path().is_file()) {
                let data = std::fs::read(entry.path())?;
                bytes += data.len() as u64;
                lines.push_str(&format!("{} {}\n", entry.file_name().to_string_lossy(), hex(&Sha256::digest(&data))));
            }
            (bytes, hex(&Sha256::digest(lines.as_bytes())))
        } else {
            let data = std::fs::read(path)?;
            (data.len() as u64, hex(&Sha256::digest(&data)))
        };
        let manifest_sha256 = path.ancestors().skip(1).take(2).find_map(|dir| manifest_sha256(dir, path));
        Ok(DatasetChecksum { file: path.display().to_string(), bytes, sha256, manifest_sha256 })
    }

    /// Whether the file matches its manifest (`None` if the manifest does not list it).
    pub fn matches_manifest(&self) -> Option<bool> {
        self.manifest_sha256.as_ref().map(|m| *m == self.sha256)
    }
}

/// What `dir/manifest.json` states for `path` (a file, or a directory's files combined as [`DatasetChecksum::of`]
/// does), looking in its `files` and `containers` lists.
fn manifest_sha256(dir: &Path, path: &Path) -> Option<String> {
    let text = std::fs::read_to_string(dir.join("manifest.json")).ok()?;
    let manifest: serde_json::Value = serde_json::from_str(&text).ok()?;
    let relative = path.strip_prefix(dir).ok()?.to_string_lossy().replace('\\', "/");
    let entries: Vec<&serde_json::Value> =
        ["files", "containers"].iter().filter_map(|list| manifest[list].as_array()).flatten().collect();
    let sha = |entry: &serde_json::Value| entry["sha256"].as_str().map(str::to_owned);
    if !path.is_dir() {
        return entries.iter().find(|entry| entry["file"] == relative.as_str()).and_then(|entry| sha(entry));
    }
    let prefix = format!("{relative}/");
    let mut members: Vec<(String, String)> = entries
        .iter()
        .filter_map(|entry| Some((entry["file"].as_str()?.strip_prefix(&prefix)?.to_owned(), sha(entry)?)))
        .collect();
    members.sort();
    let lines: String = members.iter().map(|(name, sha256)| format!("{name} {sha256}\n")).collect();
    (!members.is_empty()).then(|| hex(&Sha256::digest(lines.as_bytes())))
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

/// Everything a result file says about how it was obtained.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Provenance {
    /// [`crate::SCHEMA_VERSION`] of the file.
    pub schema_version: u32,
    /// `git rev-parse HEAD`, or `unknown`.
    pub commit: String,
    /// Whether the working tree had uncommitted changes (`git status --porcelain` not empty).
    pub dirty: Option<bool>,
    /// `rustc --version` of the compiler on the path, or `unknown` (the binary may have been built by another).
    pub rustc: String,
    /// Whether the measuring binary was built with optimisations.
    pub release_build: bool,
    /// The machine.
    pub machine: Machine,
    /// The command line.
    pub command: String,
    /// Seconds since the Unix epoch when the run started.
    pub started_unix_s: u64,
    /// Named seeds used by the run.
    pub seeds: BTreeMap<String, u64>,
    /// Dataset files used.
    pub datasets: Vec<DatasetChecksum>,
    /// Where the run's network traffic went, and so what its loopback counters mean ([`network_description`]).
    #[serde(default)]
    pub network: String,
}

/// Where this process's network traffic goes: a fresh namespace made by [`crate::netns`] (its `lo` counts only the
/// run's traffic) or the host's (other processes add to `lo`), and whether RTPS sends to same-host readers as one
/// multicast datagram (`transport::rtps::Multicast::Auto` resolved here).
pub fn network_description() -> String {
    let place = match crate::netns::inside() {
        Some(setup) if setup.multicast => "fresh network namespace (lo counts only this run), lo multicast-capable",
        Some(_) => "fresh network namespace (lo counts only this run), lo without multicast",
        None => "host network namespace (lo also counts other processes' traffic)",
    };
    let multicast = if transport::rtps::loopback_multicast_capable() {
        "RTPS multicast on: one datagram for all same-host readers"
    } else {
        "RTPS multicast off: one unicast copy per reader"
    };
    format!("{place}; {multicast}")
}

/// The command line, with the program named by its file name only (`cortex report ...`), not by the path of the
/// build directory it ran from.
fn command_line() -> String {
    let mut args = std::env::args();
    let program = args.next().map_or_else(String::new, |p| {
        Path::new(&p).file_name().map_or(p.clone(), |n| n.to_string_lossy().into_owned())
    });
    std::iter::once(program).chain(args).collect::<Vec<_>>().join(" ")
}

fn output(program: &str, args: &[&str]) -> Option<String> {
    let out = Command::new(program).args(args).output().ok()?;
    out.status.success().then(|| String::from_utf8_lossy(&out.stdout).trim().to_owned())
}

impl Provenance {
    /// The provenance of a run started now by this process.
    pub fn current() -> Provenance {
        let commit = output("git", &["rev-parse", "HEAD"]).unwrap_or_else(|| "unknown".to_owned());
        let dirty = output("git", &["status", "--porcelain", "--untracked-files=no"]).map(|s| !s.is_empty());
        Provenance {
            schema_version: crate::SCHEMA_VERSION,
            commit,
            dirty,
            rustc: output("rustc", &["--version"]).unwrap_or_else(|| "unknown".to_owned()),
            release_build: !cfg!(debug_assertions),
            machine: Machine::current(),
            command: command_line(),
            started_unix_s: std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map_or(0, |d| d.as_secs()),
            seeds: BTreeMap::new(),
            datasets: Vec::new(),
            network: network_description(),
        }
    }

    /// The commit shortened to 12 characters, with `+dirty` if the tree had changes.
    pub fn short_commit(&self) -> String {
        let short: String = self.commit.chars().take(12).collect();
        if self.dirty == Some(true) { format!("{short}+dirty") } else { short }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bundled_log_matches_its_manifest() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../datasets/logs/ouster_os1-128_1scan.mcap");
        let checksum = DatasetChecksum::of(&path).unwrap();
        assert_eq!(checksum.sha256.len(), 64);
        assert_eq!(checksum.matches_manifest(), Some(true), "{checksum:?}");
    }

    #[test]
    fn logs_in_other_containers_match_the_manifest_above_them() {
        let containers = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../datasets/logs/containers");
        for name in ["husky_10s_bz2.bag", "husky_10s_sqlite3", "custom_radar_diag_rosbag2_mcap"] {
            let checksum = DatasetChecksum::of(&containers.join(name)).unwrap();
            assert_eq!(checksum.matches_manifest(), Some(true), "{checksum:?}");
        }
    }

    #[test]
    fn provenance_names_the_machine_and_round_trips_as_json() {
        let provenance = Provenance::current();
        assert_eq!(provenance.schema_version, crate::SCHEMA_VERSION);
        assert!(provenance.machine.cpus >= 1);
        let json = serde_json::to_string(&provenance).unwrap();
        assert_eq!(serde_json::from_str::<Provenance>(&json).unwrap(), provenance);
    }
}
