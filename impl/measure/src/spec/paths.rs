//! The `payload_paths` section of an experiment set, and what `cortex bench payload` takes: payloads of several
//! sizes from one writer to N receiver processes on this host, by every path a payload can take, side by side with
//! the machine's own limit ([`crate::bench::payload`]).

use agent::Link;
use serde::{Deserialize, Deserializer, Serialize, Serializer};

/// One way a payload goes from the writer to the receivers.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum PayloadPath {
    /// A `memcpy` of the size in the measuring process: the machine's limit for one copy (no receivers).
    Memcpy,
    /// A raw iceoryx2 publish-subscribe to receiver processes (`transport::shm::limit`): no agent, no envelope, no
    /// copy out of shared memory; the limit agents over shared memory are held to.
    Iceoryx2,
    /// The agents' same-host transport alone (`transport::shm::ShmTransport`) to receiver processes: its four
    /// lanes, its wake-ups and the copy out of shared memory (or the lease) of what it receives, without the agent
    /// (no write under a lock, no envelope or delta encoded and decoded, no join, no change signal). Between raw
    /// iceoryx2 and the agents over `shm`, it says which of the two layers above iceoryx2 the difference is in.
    Transport,
    /// An agent in the measuring process writes an attribute; one agent per receiver process gets it, over this
    /// link (`cortex agent --transport`).
    Agents(Link),
}

impl PayloadPath {
    /// Every path: the two limits, the agents' shared-memory transport alone, then agents over every [`Link`] (a new link is a new path, with nothing to add
    /// here).
    pub fn all() -> Vec<PayloadPath> {
        [PayloadPath::Memcpy, PayloadPath::Iceoryx2, PayloadPath::Transport]
            .into_iter()
            .chain(Link::ALL.map(PayloadPath::Agents))
            .collect()
    }

    /// Its name on command lines and in experiment files: `memcpy`, `iceoryx2`, `transport`, or the link's name (`rtps`, `shm`).
    pub fn name(self) -> &'static str {
        match self {
            PayloadPath::Memcpy => "memcpy",
            PayloadPath::Iceoryx2 => "iceoryx2",
            PayloadPath::Transport => "transport",
            PayloadPath::Agents(link) => link.name(),
        }
    }

    /// How tables show it.
    pub fn label(self) -> String {
        match self {
            PayloadPath::Memcpy => "memcpy".into(),
            PayloadPath::Iceoryx2 => "raw iceoryx2".into(),
            PayloadPath::Transport => "shm transport".into(),
            PayloadPath::Agents(link) => format!("agents, {link}"),
        }
    }

    /// One line on what it is, for command-line help.
    pub fn summary(self) -> String {
        match self {
            PayloadPath::Memcpy => "a memcpy of the size in this process (the machine's limit for one copy)".into(),
            PayloadPath::Iceoryx2 => {
                "raw iceoryx2 publish-subscribe to receiver processes (the same-host limit)".into()
            }
            PayloadPath::Transport => {
                "the agents' shared-memory transport alone to receiver processes (no agent, no delta)".into()
            }
            PayloadPath::Agents(link) => format!("agents over --transport {link}: {}", link.summary()),
        }
    }

    /// The path named `name`, if there is one.
    pub fn from_name(name: &str) -> Option<PayloadPath> {
        PayloadPath::all().into_iter().find(|path| path.name() == name)
    }

    /// Whether it has receiver processes (all but `memcpy`).
    pub fn has_receivers(self) -> bool {
        self != PayloadPath::Memcpy
    }
}

impl std::fmt::Display for PayloadPath {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl Serialize for PayloadPath {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        serializer.serialize_str(self.name())
    }
}

impl<'de> Deserialize<'de> for PayloadPath {
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        let name = String::deserialize(deserializer)?;
        PayloadPath::from_name(&name).ok_or_else(|| {
            let known: Vec<&str> = PayloadPath::all().into_iter().map(PayloadPath::name).collect();
            serde::de::Error::custom(format!("unknown payload path {name:?} (one of {})", known.join(", ")))
        })
    }
}

/// Largest payload measured: what a shared-memory lane carries (`ShmSettings::max_sample_bytes`, 8 MiB) less room
/// for the agent's envelope.
pub const MAX_PAYLOAD_PATH_BYTES: usize = (8 << 20) - (64 << 10);
/// Most receiver processes of one cell: a shared-memory lane's endpoints (`ShmSettings::max_endpoints`, 16) less
/// the writer.
pub const MAX_PAYLOAD_PATH_RECEIVERS: u32 = 15;
/// Most samples of one cell.
pub const MAX_PAYLOAD_PATH_COUNT: u32 = 100_000;

/// What to measure: every size to every number of receivers by every path, `count` samples each at `rate_hz`.
#[derive(Clone, Debug, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct PayloadPathsExperiment {
    /// Payload sizes in bytes (at least 8: a sequence number).
    pub sizes: Vec<usize>,
    /// Numbers of receiver processes.
    pub receivers: Vec<u32>,
    /// The paths, in the order tables show them.
    pub paths: Vec<PayloadPath>,
    /// Measured samples per size, receivers and path (after `warmup` unmeasured ones).
    pub count: u32,
    /// Samples per second.
    pub rate_hz: f64,
    /// Unmeasured samples of each size before the measured ones, after the probes. A few settle discovery and the
    /// first allocations and touch the writer's shared-memory chunks. (A receiver's anti-entropy history holds one
    /// frame of the stream, the others folded into it, so it no longer needs filling: until the twelfth session it
    /// kept 64 MiB of overwritten frames, and every frame received until then landed in heap pages never touched
    /// before.)
    #[serde(default = "default_warmup")]
    pub warmup: u32,
    /// Warm-up to steady state, up to this many samples (0: off). A size of which 64 MiB ([`dsr::LogLimits`]'s
    /// payload limit) takes at most `steady_max` samples gets that many warm-up samples, plus `STEADY_MARGIN`,
    /// when that is more than `warmup` ([`PayloadPathsExperiment::warmup_for`]): 190 for a 360,960 B camera frame.
    /// That was the steady state of a history that kept every overwritten frame (until the twelfth session); the
    /// setting stays so that runs of either history compare with the same samples.
    #[serde(default)]
    pub steady_max: u32,
}

/// Warm-up samples beyond those that fill the history ([`PayloadPathsExperiment::steady_max`]): the first
/// allocations after the history starts evicting.
pub const STEADY_MARGIN: u32 = 4;

/// The default of [`PayloadPathsExperiment::warmup`].
pub const DEFAULT_PAYLOAD_PATH_WARMUP: u32 = 3;

fn default_warmup() -> u32 {
    DEFAULT_PAYLOAD_PATH_WARMUP
}

impl Default for PayloadPathsExperiment {
    /// `cortex bench payload`'s defaults: 16 B to 4 MiB (the 360,960 B camera frame among them) to 1, 2 and 8
    /// receivers by every path, 40 samples each at 20 Hz (three and a half minutes on 2 cores).
    fn default() -> Self {
        PayloadPathsExperiment {
            sizes: vec![16, 1024, 65_536, 360_960, 1 << 20, 4 << 20],
            receivers: vec![1, 2, 8],
            paths: PayloadPath::all(),
            count: 40,
            rate_hz: 20.0,
            warmup: DEFAULT_PAYLOAD_PATH_WARMUP,
            steady_max: 0,
        }
    }
}

impl PayloadPathsExperiment {
    /// The warm-up samples of `size` bytes: `warmup`, or, with [`PayloadPathsExperiment::steady_max`], the samples
    /// of 64 MiB (what a history that kept every overwritten frame held) when those are more and at most
    /// `steady_max`.
    pub fn warmup_for(&self, size: usize) -> u32 {
        let history = dsr::LogLimits::default();
        let fill = history.max_payload_bytes.div_ceil(size.max(1)).min(history.max_deltas);
        let fill = u32::try_from(fill).unwrap_or(u32::MAX).saturating_add(STEADY_MARGIN);
        if fill <= self.steady_max { self.warmup.max(fill) } else { self.warmup }
    }

    /// Checks that the numbers make cells.
    ///
    /// # Errors
    /// No size, receiver count or path; a size below 8 bytes or above [`MAX_PAYLOAD_PATH_BYTES`]; a receiver
    /// count of 0 or above [`MAX_PAYLOAD_PATH_RECEIVERS`]; a path named twice; a count of 0 or above
    /// [`MAX_PAYLOAD_PATH_COUNT`]; a warm-up above [`MAX_PAYLOAD_PATH_COUNT`]; a rate that is not positive and finite.
    pub fn validate(&self) -> anyhow::Result<()> {
        anyhow::ensure!(!self.sizes.is_empty(), "payload paths: no size");
        anyhow::ensure!(!self.receivers.is_empty(), "payload paths: no number of receivers");
        anyhow::ensure!(!self.paths.is_empty(), "payload paths: no path");
        if let Some(size) = self.sizes.iter().find(|&&s| !(8..=MAX_PAYLOAD_PATH_BYTES).contains(&s)) {
            anyhow::bail!("payload paths: a size of {size} B (8 to {MAX_PAYLOAD_PATH_BYTES})");
        }
        if let Some(n) = self.receivers.iter().find(|&&n| !(1..=MAX_PAYLOAD_PATH_RECEIVERS).contains(&n)) {
            anyhow::bail!("payload paths: {n} receivers (1 to {MAX_PAYLOAD_PATH_RECEIVERS})");
        }
        for (i, path) in self.paths.iter().enumerate() {
            anyhow::ensure!(!self.paths[..i].contains(path), "payload paths: {path} is named twice");
        }
        anyhow::ensure!(
            (1..=MAX_PAYLOAD_PATH_COUNT).contains(&self.count),
            "payload paths: a count of {} (1 to {MAX_PAYLOAD_PATH_COUNT})",
            self.count
        );
        anyhow::ensure!(
            self.warmup <= MAX_PAYLOAD_PATH_COUNT,
            "payload paths: a warm-up of {} samples (at most {MAX_PAYLOAD_PATH_COUNT})",
            self.warmup
        );
        anyhow::ensure!(
            self.steady_max <= MAX_PAYLOAD_PATH_COUNT,
            "payload paths: a steady-state warm-up of up to {} samples (at most {MAX_PAYLOAD_PATH_COUNT})",
            self.steady_max
        );
        anyhow::ensure!(
            self.rate_hz.is_finite() && self.rate_hz > 0.0,
            "payload paths: a rate of {} Hz is not a positive rate",
            self.rate_hz
        );
        Ok(())
    }

    /// The cells it measures (for progress bars): every size to every receiver count by every path with
    /// receivers, and every size once by `memcpy`.
    pub fn cells(&self) -> usize {
        let with_receivers = self.paths.iter().filter(|p| p.has_receivers()).count();
        let memcpy = usize::from(self.paths.contains(&PayloadPath::Memcpy));
        self.sizes.len() * (self.receivers.len() * with_receivers + memcpy)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_steady_warm_up_fills_the_history_for_frames_that_fill_it_soon_and_leaves_the_others_alone() {
        let experiment = PayloadPathsExperiment { warmup: 40, steady_max: 200, ..PayloadPathsExperiment::default() };
        assert_eq!(experiment.warmup_for(360_960), 186 + STEADY_MARGIN, "64 MiB of 360,960 B frames");
        assert_eq!(experiment.warmup_for(4 << 20), 40, "16 frames fill it: the warm-up is longer already");
        assert_eq!(experiment.warmup_for(16), 40, "4,096 deltas fill it: beyond the limit");
        let off = PayloadPathsExperiment { steady_max: 0, ..experiment };
        assert_eq!(off.warmup_for(360_960), 40);
    }

    #[test]
    fn every_path_is_found_by_its_own_name_and_read_back_from_its_json() {
        for path in PayloadPath::all() {
            assert_eq!(PayloadPath::from_name(path.name()), Some(path));
            let json = serde_json::to_string(&path).unwrap();
            assert_eq!(serde_json::from_str::<PayloadPath>(&json).unwrap(), path);
        }
        let error = serde_json::from_str::<PayloadPath>("\"carrier-pigeon\"").unwrap_err();
        assert!(error.to_string().contains("carrier-pigeon"), "{error}");
    }

    #[test]
    fn the_defaults_are_valid_and_numbers_that_make_no_cell_are_refused() {
        let good = PayloadPathsExperiment::default();
        good.validate().unwrap();
        assert_eq!(good.cells(), 6 * (5 * 3 + 1));
        let broken = [
            PayloadPathsExperiment { sizes: vec![], ..good.clone() },
            PayloadPathsExperiment { warmup: MAX_PAYLOAD_PATH_COUNT + 1, ..good.clone() },
            PayloadPathsExperiment { steady_max: MAX_PAYLOAD_PATH_COUNT + 1, ..good.clone() },
            PayloadPathsExperiment { sizes: vec![7], ..good.clone() },
            PayloadPathsExperiment { sizes: vec![MAX_PAYLOAD_PATH_BYTES + 1], ..good.clone() },
            PayloadPathsExperiment { receivers: vec![0], ..good.clone() },
            PayloadPathsExperiment { receivers: vec![MAX_PAYLOAD_PATH_RECEIVERS + 1], ..good.clone() },
            PayloadPathsExperiment { paths: vec![], ..good.clone() },
            PayloadPathsExperiment { paths: vec![PayloadPath::Memcpy, PayloadPath::Memcpy], ..good.clone() },
            PayloadPathsExperiment { count: 0, ..good.clone() },
            PayloadPathsExperiment { rate_hz: f64::NAN, ..good.clone() },
            PayloadPathsExperiment { rate_hz: 0.0, ..good.clone() },
        ];
        for experiment in broken {
            assert!(experiment.validate().is_err(), "{experiment:?}");
        }
    }
}
