//! Benchmarks of agents over RTPS on this host, as separate processes, each a function that returns its figures:
//! [`rtt::run`] ping-pongs one attribute between two agent processes and, in the same run, raw byte samples between
//! two processes over the same `rustdds` transport with no agent on top (the transport's limit); [`join::run`]
//! times a new agent process receiving and rebuilding a graph of N nodes; [`fanout::run`] sends large samples from
//! one writer to N reader processes and counts the bytes on the wire against N, with multicast on and off;
//! [`payload::run`] sends payloads of several sizes from one writer to N receiver processes by every path (agents
//! over each link, raw iceoryx2, memcpy) and gives each agent figure as a ratio to raw iceoryx2's.
//!
//! The other side of each measurement is a separate process, because that is what is measured: the program given
//! to each function (the `cortex` binary) is started with the helper command lines of [`helper`], and its helper
//! subcommands call [`rtt::echo`], [`join::child`], [`fanout::reader`] and [`payload::receiver`]; the join helper answers with a typed
//! [`join::JoinChildReport`] on its standard output. Where the caller runs in a fresh network namespace
//! ([`crate::netns`]), [`Counting::Socket`] reads its loopback counters at phase boundaries (discovery, then the
//! steady state), so the figures include IP, UDP and RTPS, acknowledgements, heartbeats and discovery. Figures are
//! measurements, never test assertions.

pub mod fanout;
pub mod helper;
pub mod join;
pub mod payload;
pub mod rtt;

use anyhow::Context as _;
use bytes::Bytes;
use transport::rtps::{Multicast, RtpsConfig, RtpsTransport, UpdateDelivery};

use crate::netns::LoopbackCounters;

/// How a benchmark counts the bytes on the wire.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Counting {
    /// This process runs in a fresh network namespace: its loopback counters are the measurement's traffic.
    Socket,
    /// The transport's estimates only, and why.
    EstimateOnly(String),
}

impl Counting {
    /// The loopback counters now, when this process counts socket-level bytes.
    ///
    /// # Errors
    /// The counters cannot be read.
    pub fn counters(&self) -> anyhow::Result<Option<LoopbackCounters>> {
        match self {
            Counting::Socket => Ok(Some(LoopbackCounters::read()?)),
            Counting::EstimateOnly(_) => Ok(None),
        }
    }

    /// Where the measurement ran, for headings.
    pub fn place(&self) -> &'static str {
        match self {
            Counting::Socket => "in a fresh network namespace",
            Counting::EstimateOnly(_) => "on this host's loopback",
        }
    }
}

/// The growth of the counters from `earlier` to `later`, when both were read.
fn growth(later: Option<LoopbackCounters>, earlier: Option<LoopbackCounters>) -> Option<LoopbackCounters> {
    Some(later?.since(&earlier?))
}

/// The load average of this machine (`/proc/loadavg`), reported beside every figure.
pub fn loadavg() -> String {
    std::fs::read_to_string("/proc/loadavg").map_or_else(|_| "unknown".into(), |s| s.trim().to_owned())
}

/// `auto`, `on` or `off`: a [`Multicast`] setting as command lines and reports name it.
pub fn multicast_name(multicast: Multicast) -> &'static str {
    match multicast {
        Multicast::Auto => "auto",
        Multicast::On => "on",
        Multicast::Off => "off",
    }
}

/// The byte every sample of [`payload_of`] (and raw iceoryx2's) is filled with.
const PAYLOAD_FILL: u8 = 0xA5;

/// A sample of `size` bytes (at least 8) that starts with `seq`, little-endian. Every byte is written before the
/// sample is handed over (a frame from a driver is in memory already): a zeroed allocation would map its pages only
/// when the writer's encoder first reads them, after the latency stamp.
fn payload_of(seq: u64, size: usize) -> Bytes {
    let mut bytes = vec![PAYLOAD_FILL; size.max(8)];
    bytes[..8].copy_from_slice(&seq.to_le_bytes());
    Bytes::from(bytes)
}

/// The sequence number a sample of [`payload_of`] starts with.
fn seq_of(bytes: &[u8]) -> Option<u64> {
    Some(u64::from_le_bytes(bytes.get(..8)?.try_into().ok()?))
}

/// A transport on `domain` with topics of `prefix`.
fn rtps(domain: u16, prefix: &str, multicast: Multicast, updates: UpdateDelivery) -> anyhow::Result<RtpsTransport> {
    rtps_secured(domain, prefix, multicast, updates, None)
}

/// As [`rtps`], with DDS Security's credentials in `security` (a `transport::rtps::SecurityFiles` directory).
fn rtps_secured(
    domain: u16,
    prefix: &str,
    multicast: Multicast,
    updates: UpdateDelivery,
    security: Option<&std::path::Path>,
) -> anyhow::Result<RtpsTransport> {
    RtpsTransport::new(RtpsConfig {
        domain_id: domain,
        topic_prefix: prefix.into(),
        multicast,
        updates,
        security: security.map(|dir| transport::rtps::SecurityFiles { dir: dir.to_path_buf() }),
        ..RtpsConfig::default()
    })
    .context("joining the DDS domain")
}

/// The DDS Security credentials of the two sides of a protected measurement (`cortex security init`'s
/// participant directories): the measuring process's and its helper's.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Credentials {
    /// The measuring process (the pinging agent, the serving agent).
    pub this: std::path::PathBuf,
    /// The helper process (the echoing agent, the joining agent).
    pub helper: std::path::PathBuf,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_payload_carries_its_sequence_number_at_any_size() {
        for size in [0, 8, 100] {
            let payload = payload_of(42, size);
            assert_eq!(payload.len(), size.max(8));
            assert_eq!(seq_of(&payload), Some(42));
        }
        assert_eq!(seq_of(b"short"), None);
    }

    #[test]
    fn estimates_read_no_counters() {
        let counting = Counting::EstimateOnly("test".into());
        assert_eq!(counting.counters().unwrap(), None);
        assert_eq!(counting.place(), "on this host's loopback");
        assert_eq!(growth(None, None), None);
    }
}
