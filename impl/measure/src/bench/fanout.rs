//! Bytes on the wire of one writer of large samples to N reader processes (the helpers of `bench fanout-reader`,
//! [`reader`]), with multicast on and off: probes until every reader answered, then the frames at their rate, then
//! each reader's count of what it received.

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;
use std::time::{Duration, Instant};

use anyhow::{Context as _, bail, ensure};
use bytes::Bytes;
use serde::{Deserialize, Serialize};
use transport::rtps::{Multicast, RtpsTransport, UpdateDelivery, estimated_wire_bytes};
use transport::{Channel, Transport};

use super::helper::{self, Helper};
use super::{Counting, growth, multicast_name, payload_of, rtps, seq_of};
use crate::netns::LoopbackCounters;
use crate::units::mb_from_bytes;

const PROBE: &[u8] = b"fanout-probe";
const READY: &[u8] = b"fanout-ready";
const DONE: &[u8] = b"fanout-done";
/// Most reader processes of one run.
pub const MAX_READERS: u32 = 32;

/// What to measure.
#[derive(Clone, Debug)]
pub struct FanoutConfig {
    /// Numbers of reader processes, one run each.
    pub readers: Vec<u32>,
    /// Sample size in bytes (at least 8).
    pub payload_bytes: usize,
    /// Samples per second.
    pub rate_hz: f64,
    /// Samples per run.
    pub frames: u32,
    /// Multicast settings to compare, one run per setting and reader count.
    pub multicast: Vec<Multicast>,
    /// DDS domain id.
    pub domain_id: u16,
}

impl FanoutConfig {
    /// Checks that the numbers make runs.
    ///
    /// # Errors
    /// A rate, frame count or reader count that is not positive, more than [`MAX_READERS`] readers, or a payload
    /// below 8 bytes.
    pub fn validate(&self) -> anyhow::Result<()> {
        ensure!(
            self.rate_hz > 0.0 && self.frames > 0 && !self.readers.is_empty() && !self.readers.contains(&0),
            "the rate, the frames and every reader count must be positive"
        );
        ensure!(self.payload_bytes >= 8, "the payload must be at least 8 bytes (a sequence number)");
        ensure!(self.readers.iter().all(|&n| n <= MAX_READERS), "at most {MAX_READERS} reader processes");
        Ok(())
    }
}

/// What `cortex bench fanout --json` prints (and a namespace's child process reports to its parent).
#[derive(Debug, Serialize, Deserialize)]
pub struct FanoutResult {
    /// Sample size in bytes.
    pub payload: usize,
    /// Samples per second.
    pub rate_hz: f64,
    /// Samples per run.
    pub frames: u32,
    /// Whether the bytes were counted in fresh network namespaces.
    pub netns: bool,
    /// One run per multicast setting and reader count.
    pub runs: Vec<FanoutFigures>,
    /// `--multicast on` was skipped: this host's loopback cannot carry multicast (not serialised).
    #[serde(skip)]
    pub skipped_multicast_on: bool,
}

/// Figures of one fan-out run: one writer, `readers` reader processes.
#[derive(Debug, Serialize, Deserialize)]
pub struct FanoutFigures {
    /// Reader processes.
    pub readers: u32,
    /// The multicast setting asked for.
    pub multicast_setting: String,
    /// Whether the writer's participant uses multicast.
    pub multicast: bool,
    /// Frames sent.
    pub frames: u32,
    /// Bytes per frame.
    pub payload_bytes: usize,
    /// Fewest frames any reader received.
    pub delivered_min: u64,
    /// The transport's estimate for one copy of one frame.
    pub estimated_wire_bytes_per_frame: usize,
    /// Discovery of every reader, until each answered a probe.
    pub discovery: Option<LoopbackCounters>,
    /// From the first frame until every reader reported its count.
    pub steady: Option<LoopbackCounters>,
    /// Steady-state loopback tx bytes per frame sent.
    pub bytes_per_frame: Option<f64>,
    /// `bytes_per_frame` over the payload (≈ copies on the wire).
    pub copies_per_frame: Option<f64>,
    /// `bytes_per_frame` times the frame rate, MB/s.
    pub megabytes_per_second: Option<f64>,
}

/// Every run of `config` in this process, starting `program` for the readers. Outside a namespace of our own,
/// `Multicast::On` on a host whose loopback cannot carry multicast would leave through the other
/// multicast-capable interfaces, so it is skipped and the result says so.
///
/// # Errors
/// A configuration that makes no run ([`FanoutConfig::validate`]) or a run that fails.
pub fn run(config: &FanoutConfig, counting: &Counting, program: &Path) -> anyhow::Result<FanoutResult> {
    config.validate()?;
    let mut result = FanoutResult {
        payload: config.payload_bytes,
        rate_hz: config.rate_hz,
        frames: config.frames,
        netns: *counting == Counting::Socket,
        runs: Vec::new(),
        skipped_multicast_on: false,
    };
    for &setting in &config.multicast {
        if setting == Multicast::On
            && matches!(counting, Counting::EstimateOnly(_))
            && !transport::rtps::loopback_multicast_capable()
        {
            result.skipped_multicast_on = true;
            continue;
        }
        for &readers in &config.readers {
            let figures = once(config, readers, setting, counting, program)
                .with_context(|| format!("fan-out to {readers} readers, multicast {}", multicast_name(setting)))?;
            result.runs.push(figures);
        }
    }
    Ok(result)
}

fn writer(config: &FanoutConfig, prefix: &str, setting: Multicast) -> anyhow::Result<RtpsTransport> {
    rtps(config.domain_id, prefix, setting, UpdateDelivery::Reliable)
}

fn once(
    config: &FanoutConfig,
    readers: u32,
    setting: Multicast,
    counting: &Counting,
    program: &Path,
) -> anyhow::Result<FanoutFigures> {
    let prefix = format!("fanout{}m{}n{readers}", std::process::id(), multicast_name(setting));
    let start = counting.counters()?;
    let transport = writer(config, &prefix, setting)?;
    let mut helpers = Vec::new();
    for _ in 0..readers {
        helpers.push(Helper::spawn(program, &helper::fanout_reader_args(config.domain_id, &prefix, setting))?);
    }
    discover(&transport, readers)?;
    let discovered = counting.counters()?;
    let period = Duration::from_secs_f64(1.0 / config.rate_hz);
    let mut next = Instant::now();
    for seq in 0..u64::from(config.frames) {
        transport.publish(Channel::Updates, payload_of(seq, config.payload_bytes))?;
        next += period;
        std::thread::sleep(next.saturating_duration_since(Instant::now()));
    }
    let counts = collect_counts(&transport, readers, config.frames)?;
    let end = counting.counters()?;
    drop(helpers);
    let steady = growth(end, discovered);
    let bytes_per_frame = steady.map(|s| s.tx_bytes as f64 / f64::from(config.frames));
    Ok(FanoutFigures {
        readers,
        multicast_setting: multicast_name(setting).into(),
        multicast: transport.multicast(),
        frames: config.frames,
        payload_bytes: config.payload_bytes,
        delivered_min: counts.values().copied().min().unwrap_or(0),
        estimated_wire_bytes_per_frame: estimated_wire_bytes(config.payload_bytes, true),
        discovery: growth(discovered, start),
        steady,
        bytes_per_frame,
        copies_per_frame: bytes_per_frame.map(|b| b / config.payload_bytes as f64),
        megabytes_per_second: bytes_per_frame.map(|b| mb_from_bytes(b * config.rate_hz)),
    })
}

/// Probes until every reader has answered one (its reader matched ours and ours matched its writer), then lets the
/// probes still in flight settle.
fn discover(transport: &RtpsTransport, readers: u32) -> anyhow::Result<()> {
    let mut ready = BTreeSet::new();
    let deadline = Instant::now() + Duration::from_secs(60);
    while ready.len() < readers as usize {
        if Instant::now() > deadline {
            bail!("{} of {readers} readers answered within 60 s", ready.len());
        }
        transport.publish(Channel::Calls, Bytes::from_static(PROBE))?;
        let until = Instant::now() + Duration::from_millis(100);
        while let Some(sample) = transport.recv_timeout(until.saturating_duration_since(Instant::now())) {
            if &sample.bytes[..] == READY {
                ready.insert(sample.origin);
            }
        }
    }
    while transport.recv_timeout(Duration::from_millis(300)).is_some() {}
    Ok(())
}

/// `DONE` followed by a count, little-endian.
fn done_message(count: u64) -> Bytes {
    let mut done = Vec::with_capacity(DONE.len() + 8);
    done.extend_from_slice(DONE);
    done.extend_from_slice(&count.to_le_bytes());
    Bytes::from(done)
}

/// Tells the readers the run is done after `frames` frames and waits (60 s at most) for each one's count.
fn collect_counts(
    transport: &RtpsTransport,
    readers: u32,
    frames: u32,
) -> anyhow::Result<BTreeMap<transport::EndpointId, u64>> {
    transport.publish(Channel::Calls, done_message(u64::from(frames)))?;
    let mut counts = BTreeMap::new();
    let deadline = Instant::now() + Duration::from_secs(60);
    while counts.len() < readers as usize {
        if Instant::now() > deadline {
            bail!("{} of {readers} readers reported their counts within 60 s", counts.len());
        }
        if let Some(sample) = transport.recv_timeout(Duration::from_millis(100))
            && sample.channel == Channel::Calls
            && let Some(count) = sample.bytes.strip_prefix(DONE).and_then(seq_of)
        {
            counts.insert(sample.origin, count);
        }
    }
    Ok(counts)
}

/// The fan-out reader (the helper of `bench fanout-reader`): answers probes, counts frames, and reports the count
/// when told the run is done and it has them all (or 10 s later). Returns when the writer has been silent for 60 s.
///
/// # Errors
/// The transport cannot start or refuses a publication.
pub fn reader(domain: u16, prefix: &str, multicast: Multicast) -> anyhow::Result<()> {
    let transport = rtps(domain, prefix, multicast, UpdateDelivery::Reliable)?;
    let mut frames = 0u64;
    let mut expected: Option<(u64, Instant)> = None;
    let mut last_heard = Instant::now();
    loop {
        if let Some(sample) = transport.recv_timeout(Duration::from_millis(50)) {
            last_heard = Instant::now();
            match sample.channel {
                Channel::Updates => frames += 1,
                Channel::Calls if &sample.bytes[..] == PROBE => {
                    transport.publish(Channel::Calls, Bytes::from_static(READY))?;
                }
                Channel::Calls => {
                    if let Some(total) = sample.bytes.strip_prefix(DONE).and_then(seq_of) {
                        expected = Some((total, Instant::now()));
                    }
                }
                Channel::Sync | Channel::Requests => {}
            }
        } else if last_heard.elapsed() > Duration::from_secs(60) {
            return Ok(());
        }
        if let Some((total, since)) = expected
            && (frames >= total || since.elapsed() > Duration::from_secs(10))
        {
            transport.publish(Channel::Calls, done_message(frames))?;
            expected = None;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn config() -> FanoutConfig {
        FanoutConfig {
            readers: vec![1, 2],
            payload_bytes: 360_960,
            rate_hz: 20.0,
            frames: 60,
            multicast: vec![Multicast::On, Multicast::Off],
            domain_id: 0,
        }
    }

    #[test]
    fn configurations_that_make_no_run_are_refused() {
        config().validate().unwrap();
        for broken in [
            FanoutConfig { readers: vec![0], ..config() },
            FanoutConfig { readers: vec![], ..config() },
            FanoutConfig { readers: vec![MAX_READERS + 1], ..config() },
            FanoutConfig { payload_bytes: 7, ..config() },
            FanoutConfig { rate_hz: 0.0, ..config() },
            FanoutConfig { frames: 0, ..config() },
        ] {
            assert!(broken.validate().is_err(), "{broken:?}");
        }
    }

    #[test]
    fn a_done_message_carries_its_count() {
        let done = done_message(1234);
        assert_eq!(done.strip_prefix(DONE).and_then(seq_of), Some(1234));
    }

    #[test]
    fn a_result_round_trips_through_its_json() {
        let result = FanoutResult {
            payload: 10,
            rate_hz: 20.0,
            frames: 3,
            netns: true,
            runs: Vec::new(),
            skipped_multicast_on: false,
        };
        let back: FanoutResult = serde_json::from_str(&serde_json::to_string(&result).unwrap()).unwrap();
        assert_eq!((back.payload, back.frames, back.netns), (10, 3, true));
    }
}
