//! Seeded fault injection around any [`Transport`]: loss, duplication, reordering, delay and partitions between
//! named endpoints, applied to what an endpoint *receives* (so a partition knows the origin of every sample).
//!
//! One [`FaultPlan`] is shared by the injectors of a simulation; a test changes it (partition, heal, loss rate)
//! while the system runs. Each injector draws from its own [`SplitMix64`] seeded from the plan's seed and its
//! endpoint id, and times delays by an injected [`Clock`]: given the seed, the same calls in the same order give
//! the same faults. **Held samples are bounded** ([`FaultConfig::max_held`]); past it, new samples are dropped and
//! counted as injected loss.

use std::cmp::Reverse;
use std::collections::{BTreeSet, BinaryHeap};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use bytes::Bytes;

use crate::rng::SplitMix64;
use crate::{Channel, Clock, EndpointId, Sample, Transport, TransportError, TransportStats};

/// Probabilities and delays of injected faults (serde: so a process can hand them to another).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct FaultConfig {
    /// Probability that a received sample is lost.
    pub loss: f64,
    /// Probability that a received sample is delivered twice.
    pub duplicate: f64,
    /// Probability that a sample gets an extra delay of up to `reorder_ns`, so later samples overtake it.
    pub reorder: f64,
    /// Largest extra delay of a reordered sample.
    pub reorder_ns: u64,
    /// Every sample is held between `delay_ns.0` and `delay_ns.1` nanoseconds (uniform).
    pub delay_ns: (u64, u64),
    /// Most samples held at once per endpoint.
    pub max_held: usize,
}

impl Default for FaultConfig {
    fn default() -> Self {
        FaultConfig { loss: 0.0, duplicate: 0.0, reorder: 0.0, reorder_ns: 0, delay_ns: (0, 0), max_held: 100_000 }
    }
}

#[derive(Debug)]
struct PlanState {
    config: FaultConfig,
    /// Blocked directed pairs `(from, to)`.
    blocked: BTreeSet<(EndpointId, EndpointId)>,
}

/// The faults in force, shared by every injector of a simulation.
#[derive(Clone, Debug)]
pub struct FaultPlan {
    seed: u64,
    state: Arc<Mutex<PlanState>>,
}

impl FaultPlan {
    /// A plan with `config`, and `seed` for the injectors' generators.
    pub fn new(seed: u64, config: FaultConfig) -> Self {
        FaultPlan { seed, state: Arc::new(Mutex::new(PlanState { config, blocked: BTreeSet::new() })) }
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, PlanState> {
        self.state.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Replaces the fault probabilities and delays.
    pub fn set_config(&self, config: FaultConfig) {
        self.lock().config = config;
    }

    /// The fault probabilities and delays in force.
    pub fn config(&self) -> FaultConfig {
        self.lock().config
    }

    /// Cuts every link between a member of `side_a` and a member of `side_b`, both ways.
    pub fn partition(&self, side_a: &[EndpointId], side_b: &[EndpointId]) {
        let mut state = self.lock();
        for &a in side_a {
            for &b in side_b {
                state.blocked.insert((a, b));
                state.blocked.insert((b, a));
            }
        }
    }

    /// Restores every link.
    pub fn heal(&self) {
        self.lock().blocked.clear();
    }

    /// Whether samples from `from` to `to` are blocked.
    pub fn is_blocked(&self, from: EndpointId, to: EndpointId) -> bool {
        self.lock().blocked.contains(&(from, to))
    }

    /// Wraps `inner` in an injector that follows this plan and times delays by `clock`.
    pub fn wrap<T: Transport>(&self, inner: T, clock: Arc<dyn Clock>) -> FaultInjector<T> {
        let id = inner.local_id().0;
        let seed = self.seed ^ (id as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ ((id >> 64) as u64);
        FaultInjector {
            inner,
            plan: self.clone(),
            clock,
            state: Mutex::new(InjectorState {
                rng: SplitMix64::new(seed),
                held: BinaryHeap::new(),
                next_seq: 0,
                dropped: 0,
                duplicated: 0,
            }),
        }
    }
}

/// A sample waiting for its due time, ordered by (due, arrival).
#[derive(Debug)]
struct Held {
    due_ns: u64,
    seq: u64,
    sample: Sample,
}

impl PartialEq for Held {
    fn eq(&self, other: &Self) -> bool {
        (self.due_ns, self.seq) == (other.due_ns, other.seq)
    }
}
impl Eq for Held {}
impl PartialOrd for Held {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}
impl Ord for Held {
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        (self.due_ns, self.seq).cmp(&(other.due_ns, other.seq))
    }
}

#[derive(Debug)]
struct InjectorState {
    rng: SplitMix64,
    held: BinaryHeap<Reverse<Held>>,
    next_seq: u64,
    dropped: u64,
    duplicated: u64,
}

/// A transport whose received samples go through the faults of a [`FaultPlan`].
#[derive(Debug)]
pub struct FaultInjector<T> {
    inner: T,
    plan: FaultPlan,
    clock: Arc<dyn Clock>,
    state: Mutex<InjectorState>,
}

impl<T: Transport> FaultInjector<T> {
    /// The wrapped transport.
    pub fn inner(&self) -> &T {
        &self.inner
    }

    /// Samples held (delayed) now.
    pub fn held(&self) -> usize {
        self.lock().held.len()
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, InjectorState> {
        self.state.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Runs one sample from the inner transport through the faults.
    fn admit(&self, state: &mut InjectorState, sample: Sample, now_ns: u64) {
        let me = self.inner.local_id();
        if self.plan.is_blocked(sample.origin, me) {
            state.dropped += 1;
            return;
        }
        let config = self.plan.config();
        if state.rng.chance(config.loss) {
            state.dropped += 1;
            return;
        }
        let copies = if state.rng.chance(config.duplicate) { 2 } else { 1 };
        for copy in 0..copies {
            if state.held.len() >= config.max_held {
                state.dropped += 1;
                continue;
            }
            let mut due_ns = now_ns.saturating_add(state.rng.range(config.delay_ns.0, config.delay_ns.1));
            if state.rng.chance(config.reorder) {
                due_ns = due_ns.saturating_add(state.rng.range(1, config.reorder_ns.max(1)));
            }
            if copy == 1 {
                state.duplicated += 1;
            }
            state.next_seq += 1;
            let seq = state.next_seq;
            state.held.push(Reverse(Held { due_ns, seq, sample: sample.clone() }));
        }
    }

    fn pop_due(state: &mut InjectorState, now_ns: u64) -> Option<Sample> {
        if state.held.peek().is_some_and(|Reverse(h)| h.due_ns <= now_ns) {
            return state.held.pop().map(|Reverse(h)| h.sample);
        }
        None
    }
}

impl<T: Transport> Transport for FaultInjector<T> {
    fn local_id(&self) -> EndpointId {
        self.inner.local_id()
    }

    fn publish(&self, channel: Channel, bytes: Bytes) -> Result<(), TransportError> {
        self.inner.publish(channel, bytes)
    }

    fn publish_to(&self, channel: Channel, bytes: Bytes, to: EndpointId) -> Result<(), TransportError> {
        self.inner.publish_to(channel, bytes, to)
    }

    fn sync_matches(&self) -> u64 {
        self.inner.sync_matches()
    }

    fn try_recv(&self) -> Option<Sample> {
        let now_ns = self.clock.now_ns();
        let mut state = self.lock();
        while let Some(sample) = self.inner.try_recv() {
            self.admit(&mut state, sample, now_ns);
        }
        Self::pop_due(&mut state, now_ns)
    }

    fn recv_timeout(&self, timeout: Duration) -> Option<Sample> {
        let deadline = Instant::now() + timeout;
        loop {
            if let Some(sample) = self.try_recv() {
                return Some(sample);
            }
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return None;
            }
            if let Some(sample) = self.inner.recv_timeout(left.min(Duration::from_millis(1))) {
                let now_ns = self.clock.now_ns();
                let mut state = self.lock();
                self.admit(&mut state, sample, now_ns);
            }
        }
    }

    fn stats(&self) -> TransportStats {
        let mut stats = self.inner.stats();
        let state = self.lock();
        stats.dropped_injected = state.dropped;
        stats.duplicated_injected = state.duplicated;
        stats
    }
}

impl FaultConfig {
    /// The command-line specification of this configuration (what [`FaultConfig::from_str`](std::str::FromStr)
    /// parses back to the same value): every key, e.g. `loss=0.1,duplicate=0,reorder=0,reorder-ms=0,delay-ms=0-2,
    /// max-held=100000`.
    pub fn to_spec(&self) -> String {
        let ms = |ns: u64| ns as f64 / 1e6;
        format!(
            "loss={},duplicate={},reorder={},reorder-ms={},delay-ms={}-{},max-held={}",
            self.loss,
            self.duplicate,
            self.reorder,
            ms(self.reorder_ns),
            ms(self.delay_ns.0),
            ms(self.delay_ns.1),
            self.max_held
        )
    }
}

/// A fault specification that does not parse; the message names the part and what is wrong.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("fault specification {spec:?}: {detail}")]
pub struct FaultSpecError {
    /// The whole specification.
    pub spec: String,
    /// What is wrong, and where.
    pub detail: String,
}

/// Parses a command-line fault specification: comma-separated `key=value` items, e.g.
/// `loss=0.1,duplicate=0.05,reorder=0.2,reorder-ms=10,delay-ms=0-2`. Keys: `loss`, `duplicate`, `reorder`
/// (probabilities in 0..=1), `reorder-ms` (largest extra delay), `delay-ms` (`A-B` or one value: every sample held
/// that long, uniform), `max-held` (samples held at once). `none` (or an empty string) is no fault.
///
/// ```
/// use transport::fault::FaultConfig;
/// let config: FaultConfig = "loss=0.1,delay-ms=1-3".parse().unwrap();
/// assert_eq!(config.loss, 0.1);
/// assert_eq!(config.delay_ns, (1_000_000, 3_000_000));
/// assert!("loss=2".parse::<FaultConfig>().unwrap_err().to_string().contains("between 0 and 1"));
/// ```
impl std::str::FromStr for FaultConfig {
    type Err = FaultSpecError;

    fn from_str(spec: &str) -> Result<Self, FaultSpecError> {
        let error = |detail: String| FaultSpecError { spec: spec.to_owned(), detail };
        let mut config = FaultConfig::default();
        if spec.trim().is_empty() || spec.trim() == "none" {
            return Ok(config);
        }
        for item in spec.split(',').map(str::trim) {
            let (key, value) = item.split_once('=').ok_or_else(|| error(format!("{item:?} is not key=value")))?;
            let number = |text: &str| -> Result<f64, FaultSpecError> {
                text.trim()
                    .parse::<f64>()
                    .ok()
                    .filter(|v| v.is_finite() && *v >= 0.0)
                    .ok_or_else(|| error(format!("{key}: {text:?} is not a non-negative number")))
            };
            let probability = |text: &str| -> Result<f64, FaultSpecError> {
                let p = number(text)?;
                if p > 1.0 {
                    return Err(error(format!("{key}: {p} is not a probability between 0 and 1")));
                }
                Ok(p)
            };
            let ns = |ms: f64| (ms * 1e6).round() as u64;
            match key.trim() {
                "loss" => config.loss = probability(value)?,
                "duplicate" => config.duplicate = probability(value)?,
                "reorder" => config.reorder = probability(value)?,
                "reorder-ms" => config.reorder_ns = ns(number(value)?),
                "delay-ms" => {
                    let (low, high) = match value.split_once('-') {
                        Some((low, high)) => (number(low)?, number(high)?),
                        None => (number(value)?, number(value)?),
                    };
                    if high < low {
                        return Err(error(format!("delay-ms: {value:?} ends before it starts")));
                    }
                    config.delay_ns = (ns(low), ns(high));
                }
                "max-held" => {
                    config.max_held =
                        value.trim().parse().map_err(|_| error(format!("max-held: {value:?} is not a count")))?;
                }
                other => {
                    return Err(error(format!(
                        "unknown key {other:?} (loss, duplicate, reorder, reorder-ms, delay-ms, max-held)"
                    )));
                }
            }
        }
        Ok(config)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ManualClock;
    use crate::inproc::Bus;

    fn drain<T: Transport>(t: &T) -> Vec<u8> {
        std::iter::from_fn(|| t.try_recv()).map(|s| s.bytes[0]).collect()
    }

    fn run(seed: u64, config: FaultConfig) -> (Vec<u8>, TransportStats) {
        let bus = Bus::new();
        let clock = ManualClock::new(0);
        let plan = FaultPlan::new(seed, config);
        let a = bus.attach(1024);
        let b = plan.wrap(bus.attach(1024), Arc::new(clock.clone()));
        let mut got = Vec::new();
        for i in 0..200u8 {
            a.publish(Channel::Updates, Bytes::from(vec![i])).unwrap();
            clock.advance(1_000);
            got.extend(drain(&b));
        }
        clock.advance(1_000_000_000);
        got.extend(drain(&b));
        (got, b.stats())
    }

    #[test]
    fn loss_duplication_reordering_are_seeded_and_roughly_at_rate() {
        let config = FaultConfig {
            loss: 0.1,
            duplicate: 0.1,
            reorder: 0.2,
            reorder_ns: 50_000,
            delay_ns: (0, 2_000),
            ..FaultConfig::default()
        };
        let (got, stats) = run(7, config);
        assert_eq!(run(7, config).0, got, "same seed, same faults");
        assert_ne!(run(8, config).0, got, "another seed, other faults");
        assert!((5..=40).contains(&stats.dropped_injected), "{stats:?}");
        assert!((5..=40).contains(&stats.duplicated_injected), "{stats:?}");
        assert_eq!(got.len() as u64, 200 - stats.dropped_injected + stats.duplicated_injected);
        assert!(got.windows(2).any(|w| w[0] > w[1]), "some samples overtaken");
    }

    #[test]
    fn no_faults_is_transparent() {
        let (got, stats) = run(1, FaultConfig::default());
        assert_eq!(got, (0..200u8).collect::<Vec<_>>());
        assert_eq!((stats.dropped_injected, stats.duplicated_injected), (0, 0));
    }

    #[test]
    fn delay_holds_until_due() {
        let bus = Bus::new();
        let clock = ManualClock::new(0);
        let plan = FaultPlan::new(3, FaultConfig { delay_ns: (1_000, 1_000), ..FaultConfig::default() });
        let a = bus.attach(16);
        let b = plan.wrap(bus.attach(16), Arc::new(clock.clone()));
        a.publish(Channel::Sync, Bytes::from_static(b"x")).unwrap();
        assert!(b.try_recv().is_none());
        assert_eq!(b.held(), 1);
        clock.advance(999);
        assert!(b.try_recv().is_none());
        clock.advance(1);
        assert_eq!(&b.try_recv().unwrap().bytes[..], b"x");
    }

    #[test]
    fn partition_blocks_both_ways_until_healed() {
        let bus = Bus::new();
        let clock: Arc<dyn Clock> = Arc::new(ManualClock::new(0));
        let plan = FaultPlan::new(5, FaultConfig::default());
        let a = plan.wrap(bus.attach(16), Arc::clone(&clock));
        let b = plan.wrap(bus.attach(16), Arc::clone(&clock));
        let c = plan.wrap(bus.attach(16), Arc::clone(&clock));
        plan.partition(&[a.local_id()], &[b.local_id()]);
        a.publish(Channel::Updates, Bytes::from_static(&[1])).unwrap();
        b.publish(Channel::Updates, Bytes::from_static(&[2])).unwrap();
        assert_eq!(drain(&b), Vec::<u8>::new());
        assert_eq!(drain(&a), Vec::<u8>::new());
        assert_eq!(drain(&c), vec![1, 2]);
        plan.heal();
        a.publish(Channel::Updates, Bytes::from_static(&[3])).unwrap();
        assert_eq!(drain(&b), vec![3]);
    }

    #[test]
    fn held_samples_are_bounded() {
        let bus = Bus::new();
        let clock = ManualClock::new(0);
        let config = FaultConfig { delay_ns: (10, 10), max_held: 3, ..FaultConfig::default() };
        let plan = FaultPlan::new(5, config);
        let a = bus.attach(16);
        let b = plan.wrap(bus.attach(16), Arc::new(clock.clone()));
        for i in 0..6u8 {
            a.publish(Channel::Updates, Bytes::from(vec![i])).unwrap();
        }
        assert!(b.try_recv().is_none());
        assert_eq!(b.held(), 3);
        clock.advance(10);
        assert_eq!(drain(&b), vec![0, 1, 2]);
        assert_eq!(b.stats().dropped_injected, 3);
    }

    #[test]
    fn fault_specifications_parse_or_say_what_is_wrong() {
        let config: FaultConfig =
            "loss=0.05, duplicate=0.1,reorder=0.2,reorder-ms=10,delay-ms=2,max-held=9".parse().unwrap();
        assert_eq!(
            config,
            FaultConfig {
                loss: 0.05,
                duplicate: 0.1,
                reorder: 0.2,
                reorder_ns: 10_000_000,
                delay_ns: (2_000_000, 2_000_000),
                max_held: 9
            }
        );
        assert_eq!(config.to_spec().parse::<FaultConfig>().unwrap(), config);
        let odd = FaultConfig { reorder_ns: 1_234_567, delay_ns: (3, 2_000_001), ..config };
        assert_eq!(odd.to_spec().parse::<FaultConfig>().unwrap(), odd);
        assert_eq!("none".parse::<FaultConfig>().unwrap(), FaultConfig::default());
        assert_eq!("".parse::<FaultConfig>().unwrap(), FaultConfig::default());
        for (bad, says) in [
            ("loss", "is not key=value"),
            ("loss=x", "is not a non-negative number"),
            ("loss=-0.1", "is not a non-negative number"),
            ("duplicate=1.5", "between 0 and 1"),
            ("delay-ms=3-1", "ends before it starts"),
            ("jitter=1", "unknown key \"jitter\""),
            ("max-held=-1", "is not a count"),
            ("loss=NaN", "is not a non-negative number"),
        ] {
            let error = bad.parse::<FaultConfig>().unwrap_err().to_string();
            assert!(error.contains(says) && error.contains(bad), "{bad}: {error}");
        }
    }
}
