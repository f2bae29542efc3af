//! Exact wire bytes: a measurement run in a fresh network namespace, whose loopback interface carries only that
//! measurement's traffic.
//!
//! Counting bytes from inside the transport misses what the transport does not see (acknowledgements,
//! heartbeats, discovery), and the host's loopback counters also count every other process on the machine. A new
//! network namespace has its own `lo` with counters at zero, so the counters read inside it — sampled at phase
//! boundaries (before discovery, after discovery, around the steady state) — are exactly the IP datagrams
//! (IPv4 + UDP + RTPS, acknowledgements, heartbeats and discovery included) of the processes in it. On `lo`, one
//! datagram is counted once in `tx` however many local sockets receive it, so a multicast datagram read by eight
//! processes counts once and eight unicast copies count eight times.
//!
//! [`reexec_in_fresh_netns`] runs a command under `unshare --net` after bringing `lo` up (and, for
//! [`NetnsSetup::multicast`], `ip link set lo multicast on`, `ip route add 224.0.0.0/4 dev lo` and a non-loopback
//! unicast address, `198.18.0.1/32` on `lo`: see [`NetnsSetup::multicast`]), with
//! [`NETNS_ENV`] set so the command knows where it runs ([`inside`]). [`probe`] says why a namespace cannot be
//! made (not root, `unshare` or `ip` missing, the kernel refused), so a caller can fall back to estimates and say
//! so. [`LoopbackCounters::read`] reads the namespace's own counters from `/proc/self/net/dev`
//! (`/sys/class/net` would show the namespace that mounted `/sys`, not ours).

use std::ffi::OsString;
use std::path::Path;
use std::process::{Command, ExitStatus, Stdio};

/// Environment variable set in a command started by [`reexec_in_fresh_netns`]: `lo` or `lo+multicast`.
pub const NETNS_ENV: &str = "CORTEX_NETNS";

/// How the loopback interface of a fresh namespace is set up.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct NetnsSetup {
    /// Multicast on `lo` (`ip link set lo multicast on`, route 224.0.0.0/4 via `lo`), and a non-loopback unicast
    /// address on `lo` (198.18.0.1/32, the benchmarking range), as every networked host has one. Without it a
    /// participant advertises only 127.0.0.1, which `rustdds` never picks as a unicast route when its same-host
    /// loopback preference is off (multicast on), so every message meant for *one* reader — repairs of lost
    /// fragments, GAPs, per-reader heartbeats — goes to the multicast group and is read and parsed by every
    /// participant in the namespace. One lagging receiver then loads all the others, and with 15 receiver
    /// processes on 2 cores that feedback collapsed the `rtps-processes` runs (socket receive-buffer overflows,
    /// hundreds of thousands of repair datagrams, image latency of seconds).
    pub multicast: bool,
}

impl NetnsSetup {
    fn env_value(self) -> &'static str {
        if self.multicast { "lo+multicast" } else { "lo" }
    }

    /// The shell commands that set up `lo` inside the namespace before the measured command runs.
    fn script(self) -> &'static str {
        if self.multicast {
            "set -e; ip link set lo up; ip link set lo multicast on; ip route add 224.0.0.0/4 dev lo; \
             ip addr add 198.18.0.1/32 dev lo; exec \"$@\""
        } else {
            "set -e; ip link set lo up; exec \"$@\""
        }
    }
}

/// Whether this process runs in a namespace made by [`reexec_in_fresh_netns`], and with which setup.
pub fn inside() -> Option<NetnsSetup> {
    setup_of(&std::env::var(NETNS_ENV).ok()?)
}

fn setup_of(env_value: &str) -> Option<NetnsSetup> {
    match env_value {
        "lo" => Some(NetnsSetup { multicast: false }),
        "lo+multicast" => Some(NetnsSetup { multicast: true }),
        _ => None,
    }
}

/// Why a fresh network namespace cannot be made or read.
#[derive(Debug, thiserror::Error)]
pub enum NetnsError {
    /// Creating a network namespace needs root (effective uid 0).
    #[error("not root (effective uid {euid}): creating a network namespace needs root")]
    NotRoot {
        /// The effective uid of this process.
        euid: u32,
    },
    /// A program the namespace needs is not on `PATH`.
    #[error("`{program}` not found on PATH (Debian package {package})")]
    Missing {
        /// The program (`unshare`, `ip`, `sh`).
        program: &'static str,
        /// The Debian package that provides it.
        package: &'static str,
    },
    /// `unshare --net` or the `lo` setup ran and failed.
    #[error("`{what}` failed: {detail}")]
    Refused {
        /// The command.
        what: String,
        /// Its exit status and standard error.
        detail: String,
    },
    /// The loopback counters could not be read.
    #[error("cannot read loopback counters from {path}: {detail}")]
    Counters {
        /// The file read.
        path: &'static str,
        /// What went wrong.
        detail: String,
    },
}

fn on_path(program: &str) -> bool {
    std::env::var_os("PATH").is_some_and(|path| std::env::split_paths(&path).any(|dir| dir.join(program).is_file()))
}

/// The effective uid of this process, from `/proc/self/status` (no `unsafe` call to `geteuid`).
fn effective_uid() -> Option<u32> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|line| line.starts_with("Uid:"))?;
    line.split_whitespace().nth(2)?.parse().ok()
}

/// Checks that a fresh network namespace with the given `lo` setup can be made here, by making one.
///
/// # Errors
/// [`NetnsError::NotRoot`], [`NetnsError::Missing`] or [`NetnsError::Refused`], each saying what to fix.
pub fn probe(setup: NetnsSetup) -> Result<(), NetnsError> {
    if let Some(euid) = effective_uid()
        && euid != 0
    {
        return Err(NetnsError::NotRoot { euid });
    }
    for (program, package) in [("unshare", "util-linux"), ("ip", "iproute2"), ("sh", "dash")] {
        if !on_path(program) {
            return Err(NetnsError::Missing { program, package });
        }
    }
    let output = wrap(setup, Path::new("true"), &[])
        .stdin(Stdio::null())
        .output()
        .map_err(|e| NetnsError::Refused { what: "unshare --net".into(), detail: e.to_string() })?;
    if output.status.success() {
        Ok(())
    } else {
        Err(NetnsError::Refused {
            what: format!("unshare --net sh -c '{}' true", setup.script()),
            detail: format!("{}: {}", output.status, String::from_utf8_lossy(&output.stderr).trim()),
        })
    }
}

/// The command that runs `program args` in a fresh network namespace set up as `setup`.
fn wrap(setup: NetnsSetup, program: &Path, args: &[OsString]) -> Command {
    let mut command = Command::new("unshare");
    command.args(["--net", "--", "sh", "-c", setup.script(), "sh"]).arg(program).args(args);
    command.env(NETNS_ENV, setup.env_value());
    command
}

/// Runs this very command line (same executable, same arguments) again in a fresh network namespace and waits
/// for it; its standard streams are this process's.
///
/// # Errors
/// What [`probe`] reports if a namespace cannot be made, or [`NetnsError::Refused`] if the command cannot be
/// started. A command that runs and fails is not an error here: its exit status is returned.
pub fn reexec_in_fresh_netns(setup: NetnsSetup) -> Result<ExitStatus, NetnsError> {
    let args: Vec<OsString> = std::env::args_os().skip(1).collect();
    this_executable_in_fresh_netns(setup, &args)?
        .status()
        .map_err(|e| NetnsError::Refused { what: "unshare --net (this executable)".into(), detail: e.to_string() })
}

/// A command that runs this executable with `args` in a fresh network namespace, for the caller to start (e.g.
/// with its output captured). [`probe`] has been run.
///
/// # Errors
/// What [`probe`] reports, or [`NetnsError::Refused`] if this executable cannot be found.
pub fn this_executable_in_fresh_netns(setup: NetnsSetup, args: &[OsString]) -> Result<Command, NetnsError> {
    probe(setup)?;
    let exe = std::env::current_exe()
        .map_err(|e| NetnsError::Refused { what: "finding this executable".into(), detail: e.to_string() })?;
    Ok(wrap(setup, &exe, args))
}

/// The counters of the loopback interface of this process's network namespace.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct LoopbackCounters {
    /// Bytes transmitted (IP datagrams: IPv4 header, UDP header, payload).
    pub tx_bytes: u64,
    /// Packets transmitted (IP fragments count one each).
    pub tx_packets: u64,
    /// Bytes received.
    pub rx_bytes: u64,
    /// Packets received.
    pub rx_packets: u64,
    /// Of all transmitted IP bytes in the namespace, those sent to multicast groups (`IpExt: OutMcastOctets`).
    pub tx_multicast_bytes: u64,
    /// Multicast packets transmitted in the namespace (`IpExt: OutMcastPkts`).
    pub tx_multicast_packets: u64,
}

const PROC_NET_DEV: &str = "/proc/self/net/dev";
const PROC_NET_NETSTAT: &str = "/proc/self/net/netstat";

impl LoopbackCounters {
    /// Reads the counters of `lo` in this process's namespace from `/proc/self/net/dev`, and the namespace's
    /// multicast transmit counters from `/proc/self/net/netstat`.
    ///
    /// # Errors
    /// [`NetnsError::Counters`] if a file cannot be read or lacks a well-formed `lo` or `IpExt` line.
    pub fn read() -> Result<LoopbackCounters, NetnsError> {
        let read = |path: &'static str| {
            std::fs::read_to_string(path).map_err(|e| NetnsError::Counters { path, detail: e.to_string() })
        };
        let mut counters = LoopbackCounters::parse(&read(PROC_NET_DEV)?)?;
        (counters.tx_multicast_bytes, counters.tx_multicast_packets) = parse_multicast(&read(PROC_NET_NETSTAT)?)?;
        Ok(counters)
    }

    /// Parses the `lo` line of a `/proc/net/dev` text (receive bytes and packets are columns 1–2, transmit bytes
    /// and packets columns 9–10 after the interface name).
    ///
    /// # Errors
    /// [`NetnsError::Counters`] if there is no `lo` line or it has too few or non-numeric columns.
    ///
    /// # Examples
    /// ```
    /// let text = "Inter-|   Receive |  Transmit\n face |bytes packets|bytes packets\n\
    ///             lo: 1000 10 0 0 0 0 0 0 1000 10 0 0 0 0 0 0\n";
    /// let counters = measure::netns::LoopbackCounters::parse(text).unwrap();
    /// assert_eq!((counters.tx_bytes, counters.tx_packets), (1000, 10));
    /// ```
    pub fn parse(text: &str) -> Result<LoopbackCounters, NetnsError> {
        let bad = |detail: String| NetnsError::Counters { path: PROC_NET_DEV, detail };
        let line = text
            .lines()
            .find_map(|line| line.trim_start().strip_prefix("lo:"))
            .ok_or_else(|| bad("no `lo:` line".into()))?;
        let fields: Vec<u64> = line
            .split_whitespace()
            .map(str::parse)
            .collect::<Result<_, _>>()
            .map_err(|e| bad(format!("`lo:` line `{}`: {e}", line.trim())))?;
        if fields.len() < 10 {
            return Err(bad(format!("`lo:` line has {} columns, expected 16", fields.len())));
        }
        Ok(LoopbackCounters {
            rx_bytes: fields[0],
            rx_packets: fields[1],
            tx_bytes: fields[8],
            tx_packets: fields[9],
            ..LoopbackCounters::default()
        })
    }

    /// The growth from `earlier` to `self` (zero where a counter went backwards).
    pub fn since(&self, earlier: &LoopbackCounters) -> LoopbackCounters {
        LoopbackCounters {
            tx_bytes: self.tx_bytes.saturating_sub(earlier.tx_bytes),
            tx_packets: self.tx_packets.saturating_sub(earlier.tx_packets),
            rx_bytes: self.rx_bytes.saturating_sub(earlier.rx_bytes),
            rx_packets: self.rx_packets.saturating_sub(earlier.rx_packets),
            tx_multicast_bytes: self.tx_multicast_bytes.saturating_sub(earlier.tx_multicast_bytes),
            tx_multicast_packets: self.tx_multicast_packets.saturating_sub(earlier.tx_multicast_packets),
        }
    }
}

/// `(OutMcastOctets, OutMcastPkts)` from a `/proc/net/netstat` text: its `IpExt:` lines are a header of names
/// and a line of values.
fn parse_multicast(text: &str) -> Result<(u64, u64), NetnsError> {
    let bad = |detail: String| NetnsError::Counters { path: PROC_NET_NETSTAT, detail };
    let mut lines = text.lines().filter_map(|line| line.strip_prefix("IpExt:"));
    let (Some(names), Some(values)) = (lines.next(), lines.next()) else {
        return Err(bad("no `IpExt:` header and values".into()));
    };
    let value = |wanted: &str| -> Result<u64, NetnsError> {
        let index = names
            .split_whitespace()
            .position(|name| name == wanted)
            .ok_or_else(|| bad(format!("no `{wanted}` in `IpExt:`")))?;
        let text = values.split_whitespace().nth(index).ok_or_else(|| bad(format!("no value for `{wanted}`")))?;
        text.parse().map_err(|e| bad(format!("`{wanted}` = `{text}`: {e}")))
    };
    Ok((value("OutMcastOctets")?, value("OutMcastPkts")?))
}

#[cfg(test)]
mod tests {
    use super::*;

    const SAMPLE: &str = "Inter-|   Receive                                                |  Transmit
 face |bytes    packets errs drop fifo frame compressed multicast|bytes    packets errs drop fifo colls carrier compressed
  eth0: 99 1 0 0 0 0 0 0 77 2 0 0 0 0 0 0
    lo: 1521844   13594    0    0    0     0          0         0  1521800   13590    0    0    0     0       0          0
";

    #[test]
    fn parse_reads_the_lo_line_not_another_interface() {
        let counters = LoopbackCounters::parse(SAMPLE).unwrap();
        assert_eq!(
            counters,
            LoopbackCounters {
                rx_bytes: 1_521_844,
                rx_packets: 13_594,
                tx_bytes: 1_521_800,
                tx_packets: 13_590,
                ..LoopbackCounters::default()
            }
        );
    }

    #[test]
    fn multicast_counters_are_found_by_name_and_missing_ones_are_errors() {
        let text = "TcpExt: A B\nTcpExt: 1 2\nIpExt: InNoRoutes OutMcastPkts InMcastOctets OutMcastOctets\n\
                    IpExt: 0 448 9 14503224\n";
        assert_eq!(parse_multicast(text).unwrap(), (14_503_224, 448));
        assert!(parse_multicast("IpExt: OutMcastPkts\nIpExt: 4\n").is_err());
        assert!(parse_multicast("IpExt: OutMcastPkts OutMcastOctets\nIpExt: 4 x\n").is_err());
        assert!(parse_multicast("").is_err());
    }

    #[test]
    fn malformed_or_missing_lo_lines_are_errors() {
        assert!(LoopbackCounters::parse("eth0: 1 2 3 4 5 6 7 8 9 10").is_err());
        assert!(LoopbackCounters::parse("lo: 1 2 3").is_err());
        assert!(LoopbackCounters::parse("lo: 1 2 3 4 5 6 7 8 x 10").is_err());
        assert!(LoopbackCounters::parse("").is_err());
    }

    #[test]
    fn since_subtracts_and_never_underflows() {
        let a = LoopbackCounters { tx_bytes: 10, tx_packets: 1, rx_bytes: 10, rx_packets: 1, ..Default::default() };
        let b = LoopbackCounters { tx_bytes: 30, tx_packets: 3, rx_bytes: 5, rx_packets: 1, ..Default::default() };
        let growth = b.since(&a);
        assert_eq!(growth, LoopbackCounters { tx_bytes: 20, tx_packets: 2, ..Default::default() });
    }

    #[test]
    fn setups_round_trip_through_the_environment_and_unknown_values_are_not_a_namespace() {
        for setup in [NetnsSetup { multicast: true }, NetnsSetup { multicast: false }] {
            assert_eq!(setup_of(setup.env_value()), Some(setup));
        }
        assert_eq!(setup_of(""), None);
        assert_eq!(setup_of("1"), None);
    }
}
