//! The transport's settings ([`RtpsConfig`]: multicast, best-effort updates, limits) and the QoS they give every
//! reader and writer.

use std::time::Duration;

use rustdds::policy::{Durability, History, Reliability, ResourceLimits};
use rustdds::{QosPolicies, QosPolicyBuilder};

#[cfg(doc)]
use super::RtpsTransport;
use crate::Channel;

/// Whether user data to several same-host readers goes out once, as multicast (see the module documentation).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Multicast {
    /// [`Multicast::On`] when the loopback interface is up and multicast-capable, [`Multicast::Off`] otherwise.
    #[default]
    Auto,
    /// Same-host readers share one multicast datagram (`rustdds` `same_host_loopback(false)`). Discovery then
    /// needs a multicast-capable interface, since the unicast "localhost peers" announcements are off too. Each
    /// transport runs two participants (see [`RtpsTransport::new`]); `rustdds` allows 120 participants per domain
    /// and host, so at most 60 such transports share a domain on one host.
    On,
    /// `rustdds`'s default: a reader confirmed to be on this host gets its own unicast copy over loopback.
    Off,
}

impl Multicast {
    /// Whether this setting means multicast on this host now (`Auto` asks [`loopback_multicast_capable`]).
    pub fn resolve(self) -> bool {
        match self {
            Multicast::Auto => loopback_multicast_capable(),
            Multicast::On => true,
            Multicast::Off => false,
        }
    }
}

/// Whether a loopback interface with an IPv4 address is up and multicast-capable in this network namespace,
/// as `rustdds` sees interfaces (the same `netdev` enumeration), so that it joins its multicast groups on it.
pub fn loopback_multicast_capable() -> bool {
    netdev::get_interfaces()
        .iter()
        .any(|iface| iface.is_loopback() && iface.is_up() && iface.is_multicast() && !iface.ipv4.is_empty())
}

/// This host's IPv4 addresses outside `127.0.0.0/8`, if it has any: what a multicast participant advertises.
pub fn routable_ipv4_addresses() -> Option<Vec<std::net::IpAddr>> {
    let addresses: Vec<std::net::IpAddr> = netdev::get_interfaces()
        .iter()
        .filter(|iface| iface.is_up())
        .flat_map(|iface| iface.ipv4.iter().map(|net| net.addr()))
        .filter(|addr| !addr.is_loopback())
        .map(std::net::IpAddr::V4)
        .collect();
    (!addresses.is_empty()).then_some(addresses)
}

/// Settings of an [`RtpsTransport`].
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct RtpsConfig {
    /// DDS domain id (0..=232 with the standard port mapping).
    pub domain_id: u16,
    /// Prefix of the topic names, so that several graphs can share a domain.
    pub topic_prefix: String,
    /// `ResourceLimits::max_samples` of every writer: its send window, the samples some matched reliable reader has
    /// not acknowledged before a write blocks (for [`RtpsConfig::max_blocking`], then fails).
    pub max_samples: i32,
    /// `ResourceLimits::max_samples` of every reader and topic: the samples a reader's cache keeps. `rustdds` 0.15
    /// keeps that many of the last samples received, taken or not, and at the limit evicts the oldest, taken or not
    /// (see the module documentation, "Memory"): a receiving process holds up to this many times a stream's sample
    /// size, and a burst of more than this many samples before the receiving thread takes them loses the oldest.
    pub reader_cache_samples: i32,
    /// `ResourceLimits::max_samples` of the readers and topic of large updates (samples on [`Channel::Updates`] of
    /// [`RtpsConfig::large_sample_bytes`] or more travel there, see the module documentation, "Memory"): a
    /// receiving process holds up to this many large updates, and a burst of more than this many before the
    /// receiving thread takes them loses the oldest (on the project's 2-core VM, 200 frames of 360,960 bytes
    /// written at once to a receiver that handled each in 5 ms: 22 lost of a 16-sample cache, none of a 1,024 one;
    /// none of a 16-sample cache when it handled each in 2 ms). Agents repair such losses by anti-entropy.
    pub large_cache_samples: i32,
    /// `ResourceLimits::max_samples` of the readers and topic of [`Channel::Sync`] (graph answers, repairs,
    /// snapshots: each answer to a joiner holds the whole graph). `rustdds` 0.15 keeps a reader's last samples taken
    /// or not, and an answer whose addressee's reader the writing transport does not know yet goes to every reader
    /// of the topic (the writer's own included), so with the general cache of 1,024 every agent kept the last 1,024
    /// graph answers of a graph's joins (beside a 360,960-byte frame at 20 Hz, a follower held 30 frames more after
    /// 100 joins than after 5). A receiving process holds up to this many answers; a burst of more before the
    /// receiving thread takes them loses the oldest, which the asking agent asks for again.
    pub sync_cache_samples: i32,
    /// Samples the inbox holds before the receiving thread stops taking from the readers.
    pub inbox_capacity: usize,
    /// Largest sample accepted for publishing.
    pub max_sample_bytes: usize,
    /// Samples at least this large count towards pacing, and on [`Channel::Updates`] they travel on the topic of
    /// large updates.
    pub large_sample_bytes: usize,
    /// After this many bytes of large samples, wait for acknowledgements before writing more.
    pub pace_bytes: usize,
    /// Longest wait for acknowledgements when pacing, and longest blocking of a write on a full send window.
    pub max_blocking: Duration,
    /// Create the readers in a second DDS participant, so that no writer has a reader in its own participant (see
    /// the module documentation: with one shared participant, fragmented samples are sent twice to same-host
    /// readers and delivery stalls). `false` keeps one participant per transport, for comparison only.
    pub separate_reader_participant: bool,
    /// One multicast datagram for all same-host readers, or one unicast copy each.
    pub multicast: Multicast,
    /// How samples on [`Channel::Updates`] travel: reliable like every other channel, or small ones best-effort.
    pub updates: UpdateDelivery,
    /// DDS Security credentials: every participant of the transport authenticates with them and follows the
    /// signed governance and permissions (needs the crate's `security` feature). `None`: no DDS Security.
    pub security: Option<SecurityFiles>,
    /// Create a writer for [`Channel::Requests`] alone, and readers for every channel: a participant whose
    /// permissions let it publish on the requests topic only (a read-only inspector) can then start, and
    /// publishing on another channel is refused with [`crate::TransportError::ReadOnly`].
    pub read_only: bool,
}

/// One participant's DDS Security credentials (OMG DDS Security 1.1 builtin plugins, as `rustdds` reads them): a
/// directory in the layout of a ROS 2 security enclave, holding the identity CA's certificate
/// (`identity_ca.cert.pem`), the permissions CA's certificate (`permissions_ca.cert.pem`), the signed domain
/// governance (`governance.p7s`), and this participant's identity certificate (`cert.pem`), unencrypted private
/// key (`key.pem`) and signed permissions (`permissions.p7s`).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct SecurityFiles {
    /// The directory.
    pub dir: std::path::PathBuf,
}

impl SecurityFiles {
    /// The files the directory must hold.
    pub const FILES: [&'static str; 6] =
        ["identity_ca.cert.pem", "permissions_ca.cert.pem", "governance.p7s", "cert.pem", "key.pem", "permissions.p7s"];
}

/// How samples on [`Channel::Updates`] travel (see the module documentation, "Best-effort updates").
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum UpdateDelivery {
    /// Reliable, like every other channel. `rustdds` puts a heartbeat that asks for an acknowledgement beside every
    /// DATA, so every matched reader — the writer's own transport's reader included — acknowledges every sample.
    #[default]
    Reliable,
    /// Samples of at most `max_bytes` go on a best-effort topic of their own (`{prefix}_updates_be`): no heartbeat,
    /// no acknowledgement, no repair by the DDS engine. Larger samples stay reliable. Whoever uses this repairs
    /// losses itself: agents do, by anti-entropy and by asking a peer at once when a delta shows a gap.
    BestEffort {
        /// The largest sample sent best-effort (keep it below one datagram: a lost fragment loses the sample).
        max_bytes: usize,
    },
}

impl UpdateDelivery {
    /// Best-effort for samples up to 1 KB, which stay one datagram on any usual path MTU.
    pub const BEST_EFFORT_SMALL: UpdateDelivery = UpdateDelivery::BestEffort { max_bytes: 1024 };

    /// The name used on command lines and in reports: `reliable` or `best-effort`.
    pub fn name(self) -> &'static str {
        match self {
            UpdateDelivery::Reliable => "reliable",
            UpdateDelivery::BestEffort { .. } => "best-effort",
        }
    }
}

impl Default for RtpsConfig {
    fn default() -> Self {
        RtpsConfig {
            domain_id: 0,
            topic_prefix: "dsr".into(),
            max_samples: 100_000,
            reader_cache_samples: 1024,
            large_cache_samples: 16,
            sync_cache_samples: 32,
            inbox_capacity: 65_536,
            max_sample_bytes: 256 << 20,
            large_sample_bytes: 64 << 10,
            pace_bytes: 4 << 20,
            max_blocking: Duration::from_secs(2),
            separate_reader_participant: true,
            multicast: Multicast::Auto,
            updates: UpdateDelivery::Reliable,
            security: None,
            read_only: false,
        }
    }
}

/// The largest best-effort sample of `config`, if its updates go best-effort (never for a read-only transport).
pub(super) fn best_effort_max_bytes(config: &RtpsConfig) -> Option<usize> {
    if config.read_only {
        return None;
    }
    match config.updates {
        UpdateDelivery::Reliable => None,
        UpdateDelivery::BestEffort { max_bytes } => Some(max_bytes),
    }
}

/// The QoS of every topic and reader: reliable, keep-all, volatile, a cache of
/// [`RtpsConfig::reader_cache_samples`] (a writer's is made from it, with a keep-last history and its send window).
pub fn qos(config: &RtpsConfig) -> QosPolicies {
    qos_with(config, reliable(config))
}

/// The QoS of `channel`'s topic and readers: [`qos`], with a cache of [`RtpsConfig::sync_cache_samples`] for
/// [`Channel::Sync`].
pub(super) fn channel_qos(config: &RtpsConfig, channel: Channel) -> QosPolicies {
    match channel {
        Channel::Sync => cache_qos(reliable(config), config.sync_cache_samples),
        _ => qos(config),
    }
}

/// The keep-last depth of a reliable writer: besides the samples some matched reader has not acknowledged, it keeps
/// the last one ([`writer_qos`]).
const RELIABLE_WRITER_DEPTH: i32 = 1;
/// The keep-last depth of a best-effort writer: the samples it keeps awaiting transmission, newest first
/// ([`writer_qos`]); a longer burst of small updates queued behind a congested socket loses its oldest, which agents
/// repair.
const BEST_EFFORT_WRITER_DEPTH: i32 = 1024;

/// A writer's QoS: `topic_qos` (its topic's, [`qos`] or [`qos_with`]) with a keep-last history (of
/// [`RELIABLE_WRITER_DEPTH`] or [`BEST_EFFORT_WRITER_DEPTH`], by its reliability) and the send window of
/// [`RtpsConfig::max_samples`].
///
/// Under keep-all, `rustdds` 0.15 keeps every sample a writer wrote, acknowledged or not, up to `max_samples` (100,000
/// by default): an agent streaming 360,960-byte frames over RTPS grew by twice the stream's rate (the writer's send
/// buffer, plus its own reader's topic cache), about 1 GB after 1,500 frames. Under keep-last it still never drops a
/// sample some matched reliable reader has not acknowledged, and its send window still comes from `max_samples`, not
/// from the depth; acknowledged samples beyond `depth` go at its periodic cleaning (every 6 s). A best-effort writer
/// is never acknowledged, so there `depth` caps the samples awaiting transmission, newest first.
pub(super) fn writer_qos(config: &RtpsConfig, topic_qos: &QosPolicies) -> QosPolicies {
    let depth = if topic_qos.is_reliable() { RELIABLE_WRITER_DEPTH } else { BEST_EFFORT_WRITER_DEPTH };
    let writer =
        QosPolicyBuilder::new().history(History::KeepLast { depth }).resource_limits(limits(config.max_samples));
    topic_qos.modify_by(&writer.build())
}

/// Resource limits of `max_samples` samples of the one instance of a topic without keys.
fn limits(max_samples: i32) -> ResourceLimits {
    ResourceLimits { max_samples, max_instances: 1, max_samples_per_instance: max_samples }
}

/// [`qos`] with another reliability (the best-effort updates topic).
pub(super) fn qos_with(config: &RtpsConfig, reliability: Reliability) -> QosPolicies {
    cache_qos(reliability, config.reader_cache_samples)
}

/// The QoS of the topic of large updates and its readers: [`qos`] with a cache of
/// [`RtpsConfig::large_cache_samples`].
pub(super) fn large_qos(config: &RtpsConfig) -> QosPolicies {
    cache_qos(reliable(config), config.large_cache_samples)
}

/// Reliable delivery, a write blocking for up to [`RtpsConfig::max_blocking`] on a full send window.
fn reliable(config: &RtpsConfig) -> Reliability {
    Reliability::Reliable { max_blocking_time: config.max_blocking.into() }
}

fn cache_qos(reliability: Reliability, cache_samples: i32) -> QosPolicies {
    QosPolicyBuilder::new()
        .reliability(reliability)
        .history(History::KeepAll)
        .durability(Durability::Volatile)
        .resource_limits(limits(cache_samples))
        .build()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn readers_keep_all_of_their_cache_and_writers_keep_last_with_their_window_and_the_same_reliability() {
        let config = RtpsConfig { max_samples: 777, reader_cache_samples: 55, ..RtpsConfig::default() };
        let read = qos(&config);
        let written = writer_qos(&config, &read);
        assert_eq!(read.history(), Some(History::KeepAll));
        assert_eq!(written.history(), Some(History::KeepLast { depth: 1 }));
        let cache = ResourceLimits { max_samples: 55, max_instances: 1, max_samples_per_instance: 55 };
        let window = ResourceLimits { max_samples: 777, max_instances: 1, max_samples_per_instance: 777 };
        assert_eq!((read.resource_limits(), written.resource_limits()), (Some(cache), Some(window)));
        assert_eq!(read.reliability(), written.reliability());
        assert!(written.is_reliable());
        let best_effort = writer_qos(&config, &qos_with(&config, Reliability::BestEffort));
        assert_eq!(best_effort.history(), Some(History::KeepLast { depth: 1024 }));
        assert!(!best_effort.is_reliable());
        assert_eq!(best_effort.resource_limits(), Some(window));
        let config = RtpsConfig { large_cache_samples: 9, ..config };
        let large = ResourceLimits { max_samples: 9, max_instances: 1, max_samples_per_instance: 9 };
        assert_eq!(large_qos(&config).resource_limits(), Some(large));
        assert!(large_qos(&config).is_reliable());
        assert_eq!(writer_qos(&config, &large_qos(&config)).resource_limits(), Some(window));
    }

    #[test]
    fn the_sync_channel_has_a_cache_of_its_own_and_the_other_channels_the_general_one() {
        let config = RtpsConfig { reader_cache_samples: 55, sync_cache_samples: 7, ..RtpsConfig::default() };
        let limits =
            |samples| ResourceLimits { max_samples: samples, max_instances: 1, max_samples_per_instance: samples };
        for channel in Channel::ALL {
            let read = channel_qos(&config, channel);
            let expected = if channel == Channel::Sync { 7 } else { 55 };
            assert_eq!(read.resource_limits(), Some(limits(expected)), "{}", channel.name());
            assert_eq!((read.history(), read.reliability()), (qos(&config).history(), qos(&config).reliability()));
        }
    }
}
