//! The scheduler timeline of a detector under an injected overload: how the BICA runtime degrades on the real
//! clock (issue 7).
//!
//! One [`bica::Runtime`] on the calling thread with the real monotonic clock ([`bica::MonotonicClock`]) runs the
//! `camera-detector` role of [`perception::roles`] (camera reader → colour labeller → blob detector, the tree
//! `cortex agent --role camera-detector` runs) on the frames of a bundled camera log, plus two more components in
//! the same single-threaded scheduler:
//!
//! - [`LogCamera`] writes the log's frame due at the current time (recorded timing, looping) into the camera node,
//!   as a bridge would, so a late detector sees the latest frame, not a backlog.
//! - [`Overload`] is the injected overload: another component whose step busy-waits a configured time while the
//!   clock is inside the overload window, and returns at once outside it. It is a separate component, not extra
//!   work inside the detector, so the detector's own code and cost stay what they are, and the figure shows what
//!   the scheduler promises a victim of somebody else's overrun: nothing cancelled, nothing overlapping, lateness
//!   bounded by the overrun plus one round, missed releases skipped and counted, and the nominal rate right after.
//!   It busy-waits (spins on the clock) rather than sleeps, so it really holds the scheduler thread and the CPU.
//!
//! Every scheduler decision is read back from the bica trace ring ([`bica::trace::TraceEvent`], drained every
//! 100 ms): [`fn@derive`] turns the events into one [`StepRecord`] per top-level detector step (release, start,
//! finish, lateness, skipped releases, miss), the achieved frequency over a sliding window, per-phase summaries
//! (before, during and after the overload) and the number of top-level steps that started before the previous one
//! finished. The derivation is pure, and [`run_with_clock`] takes any [`Clock`], so the tests run the same code on
//! bica's virtual clock and check exact values; only [`run`] uses the real clock, and its numbers are measurements.

use std::path::Path;

use anyhow::Context as _;
use bica::core::{ComponentId, SchedulerConfig};
use bica::prelude::*;
use bica::trace::{Caller, TraceEvent};
use bytes::Bytes;
use dsr::{NewNode, NodeId, Replica, ReplicaId};
use perception::blobs::{BlobConfig, BlobDetector};
use perception::graph::{SharedGraph, share_replica};
use perception::labelling::{ColourClass, LabelConfig, LabelTables};
use perception::sensors::{Encoding, Image, write_image};
use replay::log::{Log, ReadOptions};
use replay::ros2::{self, Ros2Message};

use crate::results::{PhaseSummary, StepRecord, Timeline, TimelineResult};
use crate::spec::TimelineExperiment;

/// Interval between the samples of the sliding-window frequency, ms.
pub const FREQUENCY_SAMPLE_MS: u64 = 10;
/// The runtime is run in slices of this length, ms, and the trace ring drained after each.
const SLICE_MS: u64 = 100;
/// Capacity of the trace ring: far above what one slice produces (a few dozen events).
const TRACE_CAPACITY: usize = 1 << 16;
/// Nanoseconds in a millisecond: the experiment's times are ms, the trace's ns.
const NS_PER_MS: u64 = 1_000_000;

/// Turns trace events (oldest first, times on the runtime's clock) into the detector's timeline. `origin_ns` is the
/// start of the run on that clock; the phases come from `experiment`'s window and duration. Pure.
pub fn derive(
    events: &[TraceEvent],
    detector: ComponentId,
    origin_ns: u64,
    experiment: &TimelineExperiment,
) -> Timeline {
    let rel = |t: u64| t.saturating_sub(origin_ns);
    let mut steps = Vec::new();
    let mut running: Vec<ComponentId> = Vec::new();
    let mut pending_miss: Option<u64> = None;
    let mut open: Option<StepRecord> = None;
    let mut last_top_finish_ns: Option<u64> = None;
    let (mut top_level_steps, mut overlaps) = (0, 0);
    for event in events {
        match *event {
            TraceEvent::Miss(miss) if miss.component == detector => pending_miss = Some(miss.expected_ns),
            TraceEvent::StepStarted { component, caller, at_ns, release_ns, lateness_ns, skipped_periods } => {
                if caller == Caller::TopLevel {
                    top_level_steps += 1;
                    if !running.is_empty() || last_top_finish_ns.is_some_and(|finish| at_ns < finish) {
                        overlaps += 1;
                    }
                    if component == detector {
                        open = Some(StepRecord {
                            release_ns: rel(release_ns),
                            start_ns: rel(at_ns),
                            finish_ns: rel(at_ns),
                            lateness_ns,
                            skipped_releases: skipped_periods,
                            miss: pending_miss == Some(release_ns),
                        });
                    }
                }
                if component == detector {
                    pending_miss = None;
                }
                running.push(component);
            }
            TraceEvent::StepFinished { component, at_ns } => {
                if let Some(position) = running.iter().rposition(|&c| c == component) {
                    running.truncate(position);
                }
                if running.is_empty() {
                    last_top_finish_ns = Some(at_ns);
                    if component == detector
                        && let Some(mut step) = open.take()
                    {
                        step.finish_ns = rel(at_ns);
                        steps.push(step);
                    }
                }
            }
            _ => {}
        }
    }

    let duration_ns = experiment.duration_ms * NS_PER_MS;
    let window_ns = experiment.window_ms * NS_PER_MS;
    let starts: Vec<u64> = steps.iter().map(|s| s.start_ns).collect();
    let mut frequency = Vec::new();
    let mut t = window_ns;
    while t <= duration_ns {
        let in_window = starts.partition_point(|&s| s <= t) - starts.partition_point(|&s| s <= t - window_ns);
        frequency.push((t, in_window as f64 / (window_ns as f64 / 1e9)));
        t += FREQUENCY_SAMPLE_MS * NS_PER_MS;
    }
    let (from_ns, until_ns) = (experiment.overload_from_ms * NS_PER_MS, experiment.overload_until_ms * NS_PER_MS);
    let phases = [("before", 0, from_ns), ("during", from_ns, until_ns), ("after", until_ns, duration_ns)]
        .into_iter()
        .map(|(name, from, until)| phase(name, from, until, &steps))
        .collect();
    Timeline {
        lateness_max_ns: steps.iter().map(|s| s.lateness_ns).max().unwrap_or(0),
        misses: steps.iter().filter(|s| s.miss).count() as u64,
        skipped_releases: steps.iter().map(|s| s.skipped_releases).sum(),
        steps,
        frequency,
        phases,
        top_level_steps,
        overlaps,
    }
}

fn phase(name: &str, from_ns: u64, until_ns: u64, steps: &[StepRecord]) -> PhaseSummary {
    let inside: Vec<&StepRecord> = steps.iter().filter(|s| s.start_ns >= from_ns && s.start_ns < until_ns).collect();
    let n = inside.len() as u64;
    let mean = |f: fn(&StepRecord) -> u64| inside.iter().map(|s| f(s)).sum::<u64>().checked_div(n).unwrap_or(0);
    PhaseSummary {
        name: name.to_owned(),
        from_ns,
        until_ns,
        steps: n,
        frequency_hz: n as f64 / ((until_ns - from_ns).max(1) as f64 / 1e9),
        lateness_max_ns: inside.iter().map(|s| s.lateness_ns).max().unwrap_or(0),
        lateness_mean_ns: mean(|s| s.lateness_ns),
        misses: inside.iter().filter(|s| s.miss).count() as u64,
        skipped_releases: inside.iter().map(|s| s.skipped_releases).sum(),
        step_mean_ns: mean(|s| s.finish_ns - s.start_ns),
    }
}

/// Reads the images of the first `sensor_msgs/Image` topic of a log, each with its log time after the first one.
///
/// # Errors
/// The log cannot be read, an image does not decode, has an encoding other than mono8, rgb8 or bgr8, or the log
/// has no images.
pub fn camera_frames(path: &Path) -> anyhow::Result<Vec<(u64, Image)>> {
    let log = Log::open(path, ReadOptions::default()).with_context(|| format!("cannot read {}", path.display()))?;
    let mut frames = Vec::new();
    let mut topic = None;
    let mut first_log_time = None;
    for message in &log.messages {
        let type_name = message.channel.type_name();
        if ros2::known_type(type_name) != Some("sensor_msgs/msg/Image")
            || *topic.get_or_insert(message.channel.id) != message.channel.id
        {
            continue;
        }
        let at = || format!("{} at log time {} ns", message.channel.topic, message.log_time);
        let Some(Ros2Message::Image(image)) = ros2::decode(type_name, &message.data).with_context(at)? else {
            anyhow::bail!("{}: not an image", at());
        };
        let encoding = Encoding::parse(&image.encoding)
            .with_context(|| format!("{}: encoding {} (need mono8, rgb8 or bgr8)", at(), image.encoding))?;
        let (width, height, step) = (image.width as usize, image.height as usize, image.step as usize);
        let row = width * encoding.channels();
        anyhow::ensure!(step >= row && image.data.len() >= step * height, "{}: step or data too short", at());
        let data = if step == row {
            image.data.slice(..row * height)
        } else {
            Bytes::from(image.data.chunks(step).take(height).flat_map(|r| &r[..row]).copied().collect::<Vec<u8>>())
        };
        let offset_ns = message.log_time - *first_log_time.get_or_insert(message.log_time);
        let image = Image::new(width, height, encoding, data).map_err(|e| anyhow::anyhow!("{}: {e}", at()))?;
        frames.push((offset_ns, image));
    }
    anyhow::ensure!(!frames.is_empty(), "{} holds no sensor_msgs/Image", path.display());
    Ok(frames)
}

/// Writes the frame of the log due at the current time (recorded timing, looping) into the camera node, once per
/// frame: a camera that keeps producing at its own rate whatever the scheduler does.
pub struct LogCamera {
    graph: SharedGraph,
    camera: NodeId,
    frames: Vec<(u64, Image)>,
    loop_ns: u64,
    origin_ns: u64,
    last_written: Option<u64>,
    written: u64,
}

impl LogCamera {
    /// A camera playing `frames` (offsets from the first frame, ascending) into `camera` from `origin_ns` on.
    pub fn new(graph: SharedGraph, camera: NodeId, frames: Vec<(u64, Image)>, origin_ns: u64) -> Self {
        let last = frames.last().map_or(0, |f| f.0);
        let gap = last.checked_div(frames.len().saturating_sub(1) as u64).unwrap_or(50 * NS_PER_MS).max(1);
        Self { graph, camera, frames, loop_ns: last + gap, origin_ns, last_written: None, written: 0 }
    }

    /// Frames written so far.
    pub fn written(&self) -> u64 {
        self.written
    }
}

impl Component for LogCamera {
    fn step(&mut self, ctx: &mut StepContext<'_>) -> Result<(), BicaError> {
        let now_ns = ctx.now_ns();
        let t = now_ns.saturating_sub(self.origin_ns);
        let within = t % self.loop_ns;
        let index = self.frames.partition_point(|f| f.0 <= within).saturating_sub(1);
        let key = (t / self.loop_ns) * self.frames.len() as u64 + index as u64;
        if self.last_written == Some(key) {
            return Ok(());
        }
        let Some((_, frame)) = self.frames.get(index) else { return Ok(()) };
        write_image(&mut *self.graph.borrow_mut(), now_ns, self.camera, frame, now_ns, key)
            .map_err(|e| BicaError::step_failed::<Self>(e.to_string()))?;
        self.last_written = Some(key);
        self.written += 1;
        Ok(())
    }
}

/// The injected overload: a component whose steps that start in `[from_ns, until_ns)` spend `busy_ns` (through
/// `spend`: a busy-wait on the real clock, an advance of a virtual one) and whose other steps return at once.
pub struct Overload {
    from_ns: u64,
    until_ns: u64,
    busy_ns: u64,
    spend: Box<dyn FnMut(u64)>,
    busy_steps: u64,
}

impl Overload {
    /// An overload window `[from_ns, until_ns)` on the runtime's clock.
    pub fn new(from_ns: u64, until_ns: u64, busy_ns: u64, spend: Box<dyn FnMut(u64)>) -> Self {
        Self { from_ns, until_ns, busy_ns, spend, busy_steps: 0 }
    }

    /// Steps that spent their busy time.
    pub fn busy_steps(&self) -> u64 {
        self.busy_steps
    }
}

impl Component for Overload {
    fn step(&mut self, ctx: &mut StepContext<'_>) -> Result<(), BicaError> {
        let now_ns = ctx.now_ns();
        if (self.from_ns..self.until_ns).contains(&now_ns) {
            (self.spend)(self.busy_ns);
            self.busy_steps += 1;
        }
        Ok(())
    }
}

/// Spins on `clock` for `busy_ns`: real work that holds the thread, unlike a sleep.
pub fn busy_wait(clock: &MonotonicClock, busy_ns: u64) {
    let end_ns = clock.now_ns().saturating_add(busy_ns);
    while clock.now_ns() < end_ns {
        std::hint::spin_loop();
    }
}

fn bica_error(what: &str) -> impl FnOnce(BicaError) -> anyhow::Error + '_ {
    move |e| anyhow::anyhow!("timeline: {what}: {e}")
}

/// Runs the experiment on `clock`: the `camera-detector` role on `frames`, the log camera and the overload
/// (spending its busy time through `spend`), for the experiment's duration, then derives the timeline.
///
/// # Errors
/// An invalid experiment, a role that cannot be built, or a scheduler error.
pub fn run_with_clock<C: Clock + Clone + 'static>(
    experiment: &TimelineExperiment,
    frames: Vec<(u64, Image)>,
    clock: C,
    spend: Box<dyn FnMut(u64)>,
) -> anyhow::Result<TimelineResult> {
    experiment.validate()?;
    let scheduler = SchedulerConfig {
        miss_tolerance_ns: experiment.miss_tolerance_us * 1_000,
        trace_capacity: TRACE_CAPACITY,
        ..SchedulerConfig::default()
    };
    let config = RuntimeConfig { scheduler, report_interval_ns: 0, ..RuntimeConfig::default() };
    let mut runtime = Runtime::new(config, clock.clone());
    let (_replica, graph) = share_replica(Replica::new(ReplicaId(4100)));
    let camera = graph
        .borrow_mut()
        .insert_node(0, NewNode::new("camera", "cam0"))
        .map_err(|e| anyhow::anyhow!("timeline: inserting the camera node: {e}"))?;
    // The same labelling as the inspector's demo on these frames: bright regions.
    let tables = LabelTables::new(LabelConfig {
        classes: vec![ColourClass { name: "bright".into(), min: [200; 3], max: [255; 3], display: [255, 255, 0] }],
    })?;
    let log_frames = frames.len() as u64;
    let period_ns = experiment.period_ms * NS_PER_MS;
    let origin_ns = clock.now_ns();
    runtime
        .register(LogCamera::new(graph.clone(), camera, frames, origin_ns), period_ns)
        .map_err(bica_error("registering the log camera"))?;
    runtime.activate::<LogCamera>().map_err(bica_error("activating the log camera"))?;
    let blobs = BlobConfig { min_area_px: 200, ..BlobConfig::default() };
    perception::roles::camera_detector(&mut runtime, graph, "cam0", tables, blobs, experiment.period_ms)?;
    let overload = Overload::new(
        origin_ns + experiment.overload_from_ms * NS_PER_MS,
        origin_ns + experiment.overload_until_ms * NS_PER_MS,
        experiment.overload_busy_ms * NS_PER_MS,
        spend,
    );
    runtime
        .register(overload, experiment.overload_period_ms * NS_PER_MS)
        .map_err(bica_error("registering the overload"))?;
    runtime.activate::<Overload>().map_err(bica_error("activating the overload"))?;
    let detector = runtime.registry().handle::<BlobDetector>().map_err(bica_error("the detector"))?.id();

    let end_ns = origin_ns + experiment.duration_ms * NS_PER_MS;
    let mut events = Vec::new();
    let mut slice_end_ns = origin_ns;
    while slice_end_ns < end_ns {
        slice_end_ns = (slice_end_ns + SLICE_MS * NS_PER_MS).min(end_ns);
        runtime.run_until(slice_end_ns).map_err(bica_error("running"))?;
        events.extend(runtime.drain_trace());
    }
    let trace_dropped = runtime.core().trace().dropped();
    let timeline = derive(&events, detector, origin_ns, experiment);
    let registry = runtime.registry();
    Ok(TimelineResult {
        experiment: experiment.clone(),
        clock: std::any::type_name::<C>().to_owned(),
        detector: registry.name(detector).unwrap_or("?").to_owned(),
        overload_component: std::any::type_name::<Overload>().to_owned(),
        log_frames,
        frames_written: registry.get::<LogCamera>().map_or(0, LogCamera::written),
        overload_busy_steps: registry.get::<Overload>().map_or(0, Overload::busy_steps),
        counters: runtime.core().counters(detector).map_err(bica_error("the detector's counters"))?,
        step_failures: runtime.step_failures(),
        trace_dropped,
        timeline,
    })
}

/// Measures the timeline on the real monotonic clock, the overload busy-waiting; relative paths against `root`.
///
/// # Errors
/// As [`camera_frames`] and [`run_with_clock`].
pub fn run(experiment: &TimelineExperiment, root: &Path) -> anyhow::Result<TimelineResult> {
    experiment.validate()?;
    let frames = camera_frames(&root.join(&experiment.log))?;
    let clock = MonotonicClock::new();
    let spin = clock.clone();
    run_with_clock(experiment, frames, clock, Box::new(move |busy_ns| busy_wait(&spin, busy_ns)))
}

#[cfg(test)]
mod tests {
    use std::path::PathBuf;

    use super::*;
    use bica::trace::MissEvent;

    fn experiment() -> TimelineExperiment {
        TimelineExperiment {
            log: PathBuf::from("datasets/logs/euroc_v1_01_easy_cam0_1s.mcap"),
            period_ms: 50,
            duration_ms: 3_000,
            overload_from_ms: 1_000,
            overload_until_ms: 2_000,
            overload_period_ms: 100,
            overload_busy_ms: 120,
            window_ms: 250,
            miss_tolerance_us: 1_000,
        }
    }

    fn log_path() -> PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../..").join(experiment().log)
    }

    /// The whole experiment on bica's virtual clock: the detector's steps take no virtual time, each overload step
    /// inside the window 120 ms. Worked by hand from the release policy: the detector runs at 0, 50, ..., 950
    /// (20 steps), then after each 120 ms overload step at 1120 (release 1050, 1 skipped), 1240 (1150, 1 skipped),
    /// 1360 (1250, 2 skipped), 1480 (1400, 1), 1600 (1500, 2), 1720 (1650, 1), 1840 (1750, 1), 1960 (1850, 2) and
    /// 2080 (2000, 1; the overload step that started at 1960 ran past the window), then on time from 2100.
    #[test]
    fn virtual_clock_run_degrades_exactly_as_the_release_policy_says() {
        let frames = camera_frames(&log_path()).unwrap();
        let clock = VirtualClock::new(0);
        let spender = clock.clone();
        let result = run_with_clock(&experiment(), frames, clock, Box::new(move |ns| spender.advance_ns(ns))).unwrap();
        let t = &result.timeline;
        let starts_ms: Vec<u64> = t.steps.iter().map(|s| s.start_ns / NS_PER_MS).collect();
        let mut expected: Vec<u64> = (0..20).map(|k| k * 50).collect();
        expected.extend([1000, 1120, 1240, 1360, 1480, 1600, 1720, 1840, 1960, 2080]);
        expected.extend((2100..3000).step_by(50));
        assert_eq!(starts_ms, expected);
        let late: Vec<(u64, u64, u64)> = t
            .steps
            .iter()
            .filter(|s| s.miss)
            .map(|s| (s.release_ns / NS_PER_MS, s.lateness_ns / NS_PER_MS, s.skipped_releases))
            .collect();
        assert_eq!(
            late,
            [(1050, 70, 1), (1150, 90, 1), (1250, 110, 2), (1400, 80, 1), (1500, 100, 2), (1650, 70, 1), (1750, 90, 1)]
                .into_iter()
                .chain([(1850, 110, 2), (2000, 80, 1)])
                .collect::<Vec<_>>()
        );
        assert!(t.steps.iter().filter(|s| !s.miss).all(|s| s.lateness_ns == 0 && s.skipped_releases == 0));
        let per_phase: Vec<(u64, f64, u64)> = t.phases.iter().map(|p| (p.steps, p.frequency_hz, p.misses)).collect();
        assert_eq!(per_phase, [(20, 20.0, 0), (9, 9.0, 8), (19, 19.0, 1)]);
        assert_eq!((t.lateness_max_ns, t.misses, t.skipped_releases, t.overlaps), (110 * NS_PER_MS, 9, 12, 0));
        assert_eq!(t.steps.len() as u64 + t.skipped_releases, 60, "every release of 0..3000 ms served or skipped");
        assert!(result.counters_agree(), "{:?} vs the trace", result.counters);
        assert_eq!((result.overload_busy_steps, result.step_failures, result.trace_dropped), (9, 0, 0));
        assert_eq!(result.log_frames, 20);
        // At most one frame per run of the log camera (48 runs, like the detector); some steps find no new frame,
        // as the recorded frames are not exactly 50 ms apart.
        assert!((1..=48).contains(&result.frames_written), "{} frames written", result.frames_written);
        // The window holds five steps at 20 Hz: 20 Hz before the overload, at most 2 steps in a window inside it.
        let at = |ms: u64| t.frequency.iter().find(|(t, _)| *t == ms * NS_PER_MS).unwrap().1;
        assert_eq!((at(250), at(1000), at(1500), at(2990)), (20.0, 20.0, 8.0, 20.0));
        assert_eq!(t.frequency.len(), 276);
    }

    fn started(component: u32, caller: Caller, at_ns: u64, release_ns: u64) -> TraceEvent {
        TraceEvent::StepStarted {
            component: ComponentId(component),
            caller,
            at_ns,
            release_ns,
            lateness_ns: at_ns - release_ns,
            skipped_periods: 0,
        }
    }

    fn finished(component: u32, at_ns: u64) -> TraceEvent {
        TraceEvent::StepFinished { component: ComponentId(component), at_ns }
    }

    #[test]
    fn derive_keeps_top_level_detector_steps_with_their_misses_and_counts_overlaps() {
        let detector = ComponentId(1);
        let miss = MissEvent {
            component: detector,
            expected_ns: 1_050 * NS_PER_MS,
            actual_ns: 1_100 * NS_PER_MS,
            lateness_ns: 50 * NS_PER_MS,
            skipped_periods: 0,
            warn: true,
            suppressed_since_last_warning: 0,
        };
        let origin = 7;
        let events = [
            started(1, Caller::TopLevel, origin, origin),
            started(0, Caller::Nested { parent: detector }, origin + 1, origin),
            finished(0, origin + 2),
            finished(1, origin + 3),
            // Component 2 overlaps the detector's finish by timestamp: counted.
            started(2, Caller::TopLevel, origin + 2, origin + 2),
            finished(2, 1_100 * NS_PER_MS),
            TraceEvent::Miss(miss),
            started(1, Caller::TopLevel, 1_100 * NS_PER_MS, 1_050 * NS_PER_MS),
            // Component 2 started while the detector is still running: counted.
            started(2, Caller::TopLevel, 1_101 * NS_PER_MS, 1_100 * NS_PER_MS),
            finished(2, 1_102 * NS_PER_MS),
            finished(1, 1_103 * NS_PER_MS),
        ];
        let t = derive(&events, detector, origin, &experiment());
        assert_eq!(
            t.steps,
            [
                StepRecord {
                    release_ns: 0,
                    start_ns: 0,
                    finish_ns: 3,
                    lateness_ns: 0,
                    skipped_releases: 0,
                    miss: false
                },
                StepRecord {
                    release_ns: 1_050 * NS_PER_MS - origin,
                    start_ns: 1_100 * NS_PER_MS - origin,
                    finish_ns: 1_103 * NS_PER_MS - origin,
                    lateness_ns: 50 * NS_PER_MS,
                    skipped_releases: 0,
                    miss: true
                },
            ]
        );
        assert_eq!((t.top_level_steps, t.overlaps, t.misses), (4, 2, 1));
        assert_eq!(t.phases.iter().map(|p| p.steps).collect::<Vec<_>>(), [1, 1, 0]);
        assert_eq!(t.phases[1].lateness_max_ns, 50 * NS_PER_MS);
        assert_eq!(t.phases[0].frequency_hz, 1.0);
    }

    #[test]
    fn a_window_outside_the_run_is_refused() {
        let bad = TimelineExperiment { overload_until_ms: 4_000, ..experiment() };
        let error = bad.validate().unwrap_err().to_string();
        assert!(error.contains("overload window"), "{error}");
        assert!(TimelineExperiment { period_ms: 0, ..experiment() }.validate().is_err());
        assert!(experiment().validate().is_ok());
    }

    #[test]
    fn the_euroc_log_gives_its_twenty_mono_frames_at_twenty_hz() {
        let frames = camera_frames(&log_path()).unwrap();
        assert_eq!(frames.len(), 20);
        assert_eq!(frames[0].0, 0);
        assert!(frames.windows(2).all(|w| (40 * NS_PER_MS..60 * NS_PER_MS).contains(&(w[1].0 - w[0].0))));
        assert_eq!((frames[0].1.width, frames[0].1.height, frames[0].1.encoding), (752, 480, Encoding::Mono8));
    }
}
