//! Runs recorded as MCAP, so Foxglove (and the `mcap` command-line tools) can open a run.
//!
//! A [`RunRecorder`] streams one run into an indexed MCAP file: chunks of about [`CHUNK_BYTES`] with their message
//! indexes, and at the end a summary section (schemas, channels, statistics, chunk indexes) and a footer. Memory is
//! bounded by one chunk plus one index entry per chunk; no message is held after it is written.
//!
//! Channels ([`Metric`] lists the metric ones):
//!
//! | topic | schema (`jsonschema`) | message encoding | log time | one message per |
//! |---|---|---|---|---|
//! | `/metrics/latency` | `cortex.WriteLatency` | `json` | application at the receiver | (write, receiver) |
//! | `/metrics/convergence` | `cortex.ConvergenceWindow` | `json` | application at the last receiver | write |
//! | `/metrics/bandwidth` | `cortex.BandwidthSample` | `json` | end of the window | 100 ms of publishing |
//! | `/metrics/summary` | `cortex.RunSummary` | `json` | end of the run | run |
//! | `/dsr/deltas` | `dsr.Delta` (encoding `""`, no schema data) | `dsr-delta-v1` | publication | published delta |
//!
//! Every metric message is a JSON object that validates against its channel's JSON Schema ([`Metric::schema`],
//! `additionalProperties: false`). A `dsr-delta-v1` message is exactly the bytes of [`dsr::Delta::encode`] (wire
//! format version [`dsr::delta::WIRE_VERSION`], documented in `dsr::delta`), as published, with no header; its MCAP sequence
//! number is the delta's index in the run. Decoding them in order with [`dsr::Delta::decode`] and applying them to an
//! empty replica with the dictionary named in the channel's `dictionary` metadata rebuilds the source's graph.
//!
//! Log and publish times are nanoseconds on the run's monotonic clock (its origin is the start of the run; the
//! metadata record [`RUN_METADATA`] gives the wall-clock start and the provenance). Log times never decrease in file
//! order: the recorder refuses a message older than the one before it.
//!
//! Why the `mcap` crate: it is the format's reference Rust implementation, maintained with the specification, and
//! writes the summary section, chunk and message indexes, statistics and CRCs that indexed readers (Foxglove,
//! `mcap info`) rely on; built without its default `zstd`/`lz4` features it adds only small pure-Rust crates (no
//! second zstd build, no C lz4), and its reader checks our files in tests. Chunks are therefore uncompressed. The
//! project's own reader ([`replay::log`]) stays the one that reads robot logs.
//!
//! Two producers use it: `cortex replay --out DIR` through [`RecordingSink`] (deltas as the bridge publishes them,
//! latencies as the in-process receivers apply them), and `cortex report` through [`write_runs`] (one file per run,
//! from each [`RunResult`]'s bounded [`WriteTimeline`]).

use std::cell::Cell;
use std::collections::BTreeMap;
use std::fs::File;
use std::io::{BufWriter, Seek, Write};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::mpsc::{Receiver, channel};

use anyhow::Context as _;
use dsr::Delta;
use hdrhistogram::Histogram;
use mcap::records::{MessageHeader, Metadata};
use replay::inproc::{Delivery, InProcNetwork, Sink, SinkError};
use serde::{Deserialize, Serialize};
use serde_json::{Value as Json, json};

use crate::clock::MonoClock;
use crate::experiment::Results;
use crate::latency::{self, LatencyRecorder, PayloadClass, Percentiles};
use crate::provenance::Provenance;
use crate::run::RunResult;

/// Topic of the graph deltas.
pub const DELTA_TOPIC: &str = "/dsr/deltas";
/// Schema name of the graph-delta channel (its schema encoding is `""`: the format is not machine-described).
pub const DELTA_SCHEMA_NAME: &str = "dsr.Delta";
/// Message encoding of the graph-delta channel: the bytes of [`dsr::Delta::encode`], wire format version 1.
pub const DELTA_MESSAGE_ENCODING: &str = "dsr-delta-v1";
/// Name of the metadata record that says how the run was obtained.
pub const RUN_METADATA: &str = "cortex.run";
/// Width of a bandwidth window, nanoseconds.
pub const BANDWIDTH_WINDOW_NS: u64 = 100_000_000;
/// Target size of a chunk before it is written out, bytes (uncompressed).
pub const CHUNK_BYTES: u64 = 1 << 20;
/// Writes whose per-write record a [`WriteTimeline`] keeps; later ones are counted, not kept.
pub const MAX_TIMELINE_WRITES: usize = 1 << 16;

/// The metric channels of a recording.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Metric {
    /// One [`WriteLatency`] per (write, receiver).
    Latency,
    /// One [`ConvergenceWindow`] per write that reached every receiver.
    Convergence,
    /// One [`BandwidthSample`] per window of [`BANDWIDTH_WINDOW_NS`].
    Bandwidth,
    /// One [`RunSummary`] at the end.
    Summary,
}

impl Metric {
    /// Every metric channel, in channel-id order.
    pub const ALL: [Metric; 4] = [Metric::Latency, Metric::Convergence, Metric::Bandwidth, Metric::Summary];

    /// The channel's topic.
    pub fn topic(self) -> &'static str {
        match self {
            Metric::Latency => "/metrics/latency",
            Metric::Convergence => "/metrics/convergence",
            Metric::Bandwidth => "/metrics/bandwidth",
            Metric::Summary => "/metrics/summary",
        }
    }

    /// The schema's name.
    pub fn schema_name(self) -> &'static str {
        match self {
            Metric::Latency => "cortex.WriteLatency",
            Metric::Convergence => "cortex.ConvergenceWindow",
            Metric::Bandwidth => "cortex.BandwidthSample",
            Metric::Summary => "cortex.RunSummary",
        }
    }

    /// The JSON Schema (draft 2020-12) of the channel's messages.
    pub fn schema(self) -> Json {
        let int = |description: &str| json!({ "type": "integer", "minimum": 0, "description": description });
        let class = json!({
            "type": "string",
            "enum": PayloadClass::ALL.map(PayloadClass::name),
            "description": "payload class of the message the write came from"
        });
        let (title, description, properties) = match self {
            Metric::Latency => (
                self.schema_name(),
                "one write applied at one receiver",
                json!({
                    "seq": int("index of the write (delta) in the run"),
                    "class": class,
                    "receiver": int("receiving agent (1 to N-1; agent 0 is the source)"),
                    "publish_ns": int("publication at the source, ns on the run's clock"),
                    "apply_ns": int("application at the receiver (decoded and joined), ns on the run's clock"),
                    "latency_ns": int("apply_ns - publish_ns"),
                    "bytes": int("bytes of the published sample"),
                }),
            ),
            Metric::Convergence => (
                self.schema_name(),
                "the time until every receiver reflects one write",
                json!({
                    "seq": int("index of the write (delta) in the run"),
                    "class": class,
                    "publish_ns": int("publication at the source, ns on the run's clock"),
                    "converged_ns": int("application at the last receiver, ns on the run's clock"),
                    "window_ns": int("converged_ns - publish_ns (at least 1)"),
                    "receivers": int("receivers that applied it (all of them)"),
                }),
            ),
            Metric::Bandwidth => (
                self.schema_name(),
                "bytes published by the source in one window",
                json!({
                    "window_start_ns": int("start of the window, ns on the run's clock"),
                    "window_ns": int("width of the window"),
                    "writes": int("writes published in the window"),
                    "bytes": int("bytes published in the window"),
                    "bytes_per_second": { "type": "number", "minimum": 0, "description": "bytes / window" },
                }),
            ),
            Metric::Summary => {
                let pct = percentiles_schema();
                (
                    self.schema_name(),
                    "what one run measured",
                    json!({
                        "run": { "type": "string", "description": "the workload: a log file name or a synthetic one" },
                        "transport": { "type": "string", "description": "inproc or rtps, with +faults if injected" },
                        "agents": int("agents, the source included"),
                        "seed": int("seed of the delivery order or fault injector"),
                        "writes": int("writes (deltas) published"),
                        "published_bytes": int("bytes published by the source"),
                        "latency": pct,
                        "latency_by_class": {
                            "type": "object",
                            "description": "latency per payload class",
                            "additionalProperties": pct,
                        },
                        "convergence": pct,
                        "writes_not_everywhere": int("writes some receiver never applied"),
                        "end_convergence_ns": {
                            "type": ["integer", "null"],
                            "minimum": 0,
                            "description": "last application anywhere - last publication, if every digest is equal",
                        },
                        "digests_equal": { "type": "boolean", "description": "every receiver has the source's graph" },
                        "digests": {
                            "type": "array",
                            "items": { "type": "string" },
                            "description": "graph digests, source first (empty when the run did not keep them)",
                        },
                        "writes_recorded": int("writes with per-write messages in this file"),
                    }),
                )
            }
        };
        let required: Vec<String> = properties.as_object().map(|o| o.keys().cloned().collect()).unwrap_or_default();
        json!({
            "$schema": "https://json-schema.org/draft/2020-12/schema",
            "title": title,
            "description": description,
            "type": "object",
            "properties": properties,
            "required": required,
            "additionalProperties": false,
        })
    }
}

fn percentiles_schema() -> Json {
    let int = json!({ "type": "integer", "minimum": 0 });
    let properties: serde_json::Map<String, Json> = ["count", "p50_ns", "p90_ns", "p99_ns", "p999_ns", "max_ns"]
        .into_iter()
        .map(|k| (k.to_owned(), int.clone()))
        .chain([("mean_ns".to_owned(), json!({ "type": "number", "minimum": 0 }))])
        .collect();
    let required: Vec<String> = properties.keys().cloned().collect();
    json!({
        "type": "object",
        "description": "percentiles of a histogram, ns (all zero when empty)",
        "properties": properties,
        "required": required,
        "additionalProperties": false,
    })
}

/// A message of `/metrics/latency`: one write applied at one receiver.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct WriteLatency {
    /// Index of the write (delta) in the run.
    pub seq: u64,
    /// Payload class of the message it came from.
    pub class: PayloadClass,
    /// Receiving agent, 1 to N-1 (agent 0 is the source).
    pub receiver: u32,
    /// Publication at the source, ns on the run's clock.
    pub publish_ns: u64,
    /// Application at the receiver, ns on the run's clock.
    pub apply_ns: u64,
    /// `apply_ns - publish_ns`.
    pub latency_ns: u64,
    /// Bytes of the published sample.
    pub bytes: u64,
}

/// A message of `/metrics/convergence`: the time until every receiver reflects one write.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct ConvergenceWindow {
    /// Index of the write (delta) in the run.
    pub seq: u64,
    /// Payload class of the message it came from.
    pub class: PayloadClass,
    /// Publication at the source, ns on the run's clock.
    pub publish_ns: u64,
    /// Application at the last receiver, ns on the run's clock.
    pub converged_ns: u64,
    /// `converged_ns - publish_ns`, at least 1.
    pub window_ns: u64,
    /// Receivers that applied it.
    pub receivers: u32,
}

/// A message of `/metrics/bandwidth`: bytes published by the source in one window.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BandwidthSample {
    /// Start of the window, ns on the run's clock.
    pub window_start_ns: u64,
    /// Width of the window, ns.
    pub window_ns: u64,
    /// Writes published in the window.
    pub writes: u64,
    /// Bytes published in the window.
    pub bytes: u64,
    /// `bytes` per second of the window.
    pub bytes_per_second: f64,
}

/// The message of `/metrics/summary`: what one run measured.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RunSummary {
    /// The workload: a log file name or a synthetic one.
    pub run: String,
    /// `inproc` or `rtps`, with `+faults` when the fault injector was in the way.
    pub transport: String,
    /// Agents, the source included.
    pub agents: u32,
    /// Seed of the delivery order or of the fault injector.
    pub seed: u64,
    /// Writes (deltas) published.
    pub writes: u64,
    /// Bytes published by the source.
    pub published_bytes: u64,
    /// Latency of every (write, receiver) pair.
    pub latency: Percentiles,
    /// Latency per payload class, by the class's name.
    pub latency_by_class: BTreeMap<String, Percentiles>,
    /// Per-write convergence windows.
    pub convergence: Percentiles,
    /// Writes some receiver never applied.
    pub writes_not_everywhere: u64,
    /// Last application anywhere − last publication, when every receiver ended with the source's digest.
    pub end_convergence_ns: Option<u64>,
    /// Whether every receiver ended with the source's digest.
    pub digests_equal: bool,
    /// The graph digests, source first (empty when the run did not keep them).
    pub digests: Vec<String>,
    /// Writes with per-write messages in the file (a [`WriteTimeline`] keeps at most [`MAX_TIMELINE_WRITES`]).
    pub writes_recorded: u64,
}

/// Messages written, per topic.
pub type RecordCounts = BTreeMap<&'static str, u64>;

/// Closes 100 ms windows of published bytes as time passes.
#[derive(Debug, Default)]
struct Windows {
    start_ns: Option<u64>,
    writes: u64,
    bytes: u64,
}

impl Windows {
    fn sample(&self, start_ns: u64) -> BandwidthSample {
        BandwidthSample {
            window_start_ns: start_ns,
            window_ns: BANDWIDTH_WINDOW_NS,
            writes: self.writes,
            bytes: self.bytes,
            bytes_per_second: self.bytes as f64 * 1e9 / BANDWIDTH_WINDOW_NS as f64,
        }
    }
}

/// Streams one run into an MCAP file (see the module documentation for the channels).
pub struct RunRecorder<W: Write + Seek> {
    writer: mcap::Writer<W>,
    metric_channels: BTreeMap<Metric, u16>,
    delta_channel: Option<u16>,
    sequences: BTreeMap<u16, u32>,
    last_log_ns: u64,
    windows: Windows,
    counts: RecordCounts,
}

impl<W: Write + Seek> std::fmt::Debug for RunRecorder<W> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RunRecorder").field("counts", &self.counts).field("last_log_ns", &self.last_log_ns).finish()
    }
}

impl RunRecorder<BufWriter<File>> {
    /// Creates (or replaces) the file at `path` and starts a recording with `metadata` (see [`RunRecorder::new`]).
    ///
    /// # Errors
    /// The file cannot be created or written.
    pub fn create(path: &Path, metadata: BTreeMap<String, String>) -> anyhow::Result<Self> {
        let file = File::create(path).with_context(|| format!("cannot create {}", path.display()))?;
        RunRecorder::new(BufWriter::new(file), metadata).with_context(|| format!("cannot write {}", path.display()))
    }
}

impl<W: Write + Seek> RunRecorder<W> {
    /// Starts a recording into `out`: the header, the metric schemas and channels, and the metadata record
    /// [`RUN_METADATA`] with `metadata` (how the run was obtained).
    ///
    /// # Errors
    /// `out` cannot be written.
    pub fn new(out: W, metadata: BTreeMap<String, String>) -> anyhow::Result<Self> {
        let options = mcap::WriteOptions::new()
            .profile("")
            .library(format!("cortex-rs measure {}", env!("CARGO_PKG_VERSION")))
            .chunk_size(Some(CHUNK_BYTES));
        let mut writer = options.create(out).context("cannot start the MCAP file")?;
        // Metadata first: a metadata record closes the open chunk, and the schemas belong with the first messages.
        writer.write_metadata(&Metadata { name: RUN_METADATA.to_owned(), metadata })?;
        let mut metric_channels = BTreeMap::new();
        for metric in Metric::ALL {
            let schema = serde_json::to_vec(&metric.schema())?;
            let schema_id = writer.add_schema(metric.schema_name(), "jsonschema", &schema)?;
            let channel = writer.add_channel(schema_id, metric.topic(), "json", &BTreeMap::new())?;
            metric_channels.insert(metric, channel);
        }
        Ok(RunRecorder {
            writer,
            metric_channels,
            delta_channel: None,
            sequences: BTreeMap::new(),
            last_log_ns: 0,
            windows: Windows::default(),
            counts: RecordCounts::new(),
        })
    }

    /// Adds the graph-delta channel; `dictionary` says which type dictionary a replica needs to apply the deltas
    /// (kept in the channel's `dictionary` metadata).
    ///
    /// # Errors
    /// The file cannot be written.
    pub fn add_delta_channel(&mut self, dictionary: &str) -> anyhow::Result<()> {
        let schema_id = self.writer.add_schema(DELTA_SCHEMA_NAME, "", &[])?;
        let metadata = BTreeMap::from([
            ("wire_version".to_owned(), dsr::delta::WIRE_VERSION.to_string()),
            ("dictionary".to_owned(), dictionary.to_owned()),
            (
                "format".to_owned(),
                "the bytes of dsr::Delta::encode as published (postcard behind a version byte; see dsr::delta)"
                    .to_owned(),
            ),
        ]);
        let channel = self.writer.add_channel(schema_id, DELTA_TOPIC, DELTA_MESSAGE_ENCODING, &metadata)?;
        self.delta_channel = Some(channel);
        Ok(())
    }

    /// Messages written so far, per topic.
    pub fn counts(&self) -> &RecordCounts {
        &self.counts
    }

    /// Moves the recording's time to `log_ns`: closes the bandwidth windows that end by then.
    fn advance(&mut self, log_ns: u64) -> anyhow::Result<()> {
        anyhow::ensure!(
            log_ns >= self.last_log_ns,
            "a recording's log times never decrease: {log_ns} ns after {} ns",
            self.last_log_ns
        );
        while let Some(start) = self.windows.start_ns.filter(|s| s + BANDWIDTH_WINDOW_NS <= log_ns) {
            let sample = self.windows.sample(start);
            self.windows = Windows { start_ns: Some(start + BANDWIDTH_WINDOW_NS), writes: 0, bytes: 0 };
            self.write_json(Metric::Bandwidth, start + BANDWIDTH_WINDOW_NS, start, &sample)?;
        }
        self.last_log_ns = log_ns;
        Ok(())
    }

    fn write_raw(
        &mut self,
        channel: u16,
        topic: &'static str,
        log_ns: u64,
        publish_ns: u64,
        data: &[u8],
    ) -> anyhow::Result<()> {
        let sequence = self.sequences.entry(channel).or_insert(0);
        let header =
            MessageHeader { channel_id: channel, sequence: *sequence, log_time: log_ns, publish_time: publish_ns };
        *sequence = sequence.wrapping_add(1);
        self.writer.write_to_known_channel(&header, data).with_context(|| format!("cannot write a {topic} message"))?;
        *self.counts.entry(topic).or_insert(0) += 1;
        Ok(())
    }

    fn write_json(
        &mut self,
        metric: Metric,
        log_ns: u64,
        publish_ns: u64,
        value: &impl Serialize,
    ) -> anyhow::Result<()> {
        let data = serde_json::to_vec(value)?;
        let channel = self.metric_channels[&metric];
        self.write_raw(channel, metric.topic(), log_ns, publish_ns, &data)
    }

    /// Counts `bytes` published at `publish_ns` in the bandwidth windows (done by [`RunRecorder::delta`] for a
    /// recorded delta; call it directly when the deltas are not recorded).
    ///
    /// # Errors
    /// `publish_ns` before the last log time, or a window that cannot be written.
    pub fn published(&mut self, publish_ns: u64, bytes: u64) -> anyhow::Result<()> {
        self.advance(publish_ns)?;
        let start = *self.windows.start_ns.get_or_insert(publish_ns - publish_ns % BANDWIDTH_WINDOW_NS);
        debug_assert!(publish_ns >= start && publish_ns < start + BANDWIDTH_WINDOW_NS);
        self.windows.writes += 1;
        self.windows.bytes += bytes;
        Ok(())
    }

    /// Records the encoded delta `bytes` (delta number `index` of the run) published at `publish_ns`.
    ///
    /// # Errors
    /// No delta channel ([`RunRecorder::add_delta_channel`]), a time before the last one, or a write that fails.
    pub fn delta(&mut self, index: u64, publish_ns: u64, bytes: &[u8]) -> anyhow::Result<()> {
        let channel = self.delta_channel.context("the recording has no delta channel")?;
        self.published(publish_ns, bytes.len() as u64)?;
        self.sequences.insert(channel, index as u32);
        self.write_raw(channel, DELTA_TOPIC, publish_ns, publish_ns, bytes)
    }

    /// Records one write applied at one receiver (log time: `apply_ns`).
    ///
    /// # Errors
    /// A time before the last one, or a write that fails.
    pub fn latency(&mut self, sample: &WriteLatency) -> anyhow::Result<()> {
        self.advance(sample.apply_ns)?;
        self.write_json(Metric::Latency, sample.apply_ns, sample.publish_ns, sample)
    }

    /// Records a write's convergence window (log time: `converged_ns`).
    ///
    /// # Errors
    /// A time before the last one, or a write that fails.
    pub fn convergence(&mut self, window: &ConvergenceWindow) -> anyhow::Result<()> {
        self.advance(window.converged_ns)?;
        self.write_json(Metric::Convergence, window.converged_ns, window.publish_ns, window)
    }

    /// Records the run's summary at `log_ns` (the end of the run).
    ///
    /// # Errors
    /// A time before the last one, or a write that fails.
    pub fn summary(&mut self, log_ns: u64, summary: &RunSummary) -> anyhow::Result<()> {
        self.advance(log_ns)?;
        self.write_json(Metric::Summary, log_ns, log_ns, summary)
    }

    /// Closes the open bandwidth window, writes the summary section and the footer, and returns the output and the
    /// messages written per topic.
    ///
    /// # Errors
    /// The file cannot be written.
    pub fn finish(mut self) -> anyhow::Result<(W, RecordCounts)> {
        if let Some(start) = self.windows.start_ns {
            self.advance(start + BANDWIDTH_WINDOW_NS)?;
        }
        self.writer.finish().context("cannot write the MCAP summary")?;
        Ok((self.writer.into_inner(), self.counts))
    }
}

/// Finishes a recording into a file and flushes it.
///
/// # Errors
/// The file cannot be written.
pub fn finish_file(recorder: RunRecorder<BufWriter<File>>) -> anyhow::Result<RecordCounts> {
    let (mut out, counts) = recorder.finish()?;
    out.flush().context("cannot flush the MCAP file")?;
    Ok(counts)
}

/// The provenance as metadata of a recording, plus the clock's meaning.
pub fn provenance_metadata(provenance: &Provenance) -> BTreeMap<String, String> {
    let seeds = provenance.seeds.iter().map(|(k, v)| format!("{k}={v}")).collect::<Vec<_>>().join(", ");
    BTreeMap::from([
        ("commit".to_owned(), provenance.short_commit()),
        ("rustc".to_owned(), provenance.rustc.clone()),
        ("build".to_owned(), if provenance.release_build { "release" } else { "debug" }.to_owned()),
        ("machine".to_owned(), provenance.machine.summary()),
        ("command".to_owned(), provenance.command.clone()),
        ("started_unix_s".to_owned(), provenance.started_unix_s.to_string()),
        ("seeds".to_owned(), seeds),
        ("clock".to_owned(), "log and publish times are ns on the run's monotonic clock".to_owned()),
    ])
}

/// Per-write record of a run: publication and application times of its first [`MAX_TIMELINE_WRITES`] writes, kept
/// in a [`RunResult`] so the run can be recorded after it ends.
#[derive(Clone, Debug, Default)]
pub struct WriteTimeline {
    receivers: u32,
    writes: Vec<TimelineWrite>,
    /// `writes.len() × receivers` application times, write-major; `u64::MAX` where never applied.
    applied_ns: Vec<u64>,
    not_kept: u64,
}

/// One write of a [`WriteTimeline`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TimelineWrite {
    /// Payload class of the message it came from.
    pub class: PayloadClass,
    /// Bytes of the published sample.
    pub bytes: u64,
    /// Publication at the source, ns on the run's clock.
    pub publish_ns: u64,
}

impl WriteTimeline {
    /// An empty timeline of a run with `receivers` receivers.
    pub fn new(receivers: u32) -> Self {
        WriteTimeline { receivers, ..WriteTimeline::default() }
    }

    /// Adds the next write with its application time at each receiver (`None`: never applied), in receiver order.
    /// Past [`MAX_TIMELINE_WRITES`] the write is only counted.
    pub fn push(&mut self, write: TimelineWrite, applied_ns: impl IntoIterator<Item = Option<u64>>) {
        if self.writes.len() >= MAX_TIMELINE_WRITES {
            self.not_kept += 1;
            return;
        }
        let before = self.applied_ns.len();
        self.applied_ns.extend(applied_ns.into_iter().map(|t| t.unwrap_or(u64::MAX)));
        assert_eq!(self.applied_ns.len() - before, self.receivers as usize, "one time per receiver");
        self.writes.push(write);
    }

    /// Receivers of the run.
    pub fn receivers(&self) -> u32 {
        self.receivers
    }

    /// The writes kept, in publication order.
    pub fn writes(&self) -> &[TimelineWrite] {
        &self.writes
    }

    /// When write `seq` was applied at receiver `receiver` (0-based), if it was.
    pub fn applied_ns(&self, seq: usize, receiver: usize) -> Option<u64> {
        let at = self.applied_ns[seq * self.receivers as usize + receiver];
        (at != u64::MAX).then_some(at)
    }

    /// Writes published but not kept.
    pub fn not_kept(&self) -> u64 {
        self.not_kept
    }
}

/// The summary of a [`RunResult`].
pub fn summary_of(result: &RunResult) -> RunSummary {
    RunSummary {
        run: result.workload.clone(),
        transport: result.transport.clone(),
        agents: result.agents,
        seed: result.seed,
        writes: result.writes,
        published_bytes: result.sample_bytes,
        latency: result.latency,
        latency_by_class: result.latency_by_class.iter().map(|(c, p)| (c.name().to_owned(), *p)).collect(),
        convergence: result.convergence,
        writes_not_everywhere: result.writes_not_everywhere,
        end_convergence_ns: result.end_convergence_ns,
        digests_equal: result.digests_equal,
        digests: Vec::new(),
        writes_recorded: result.timeline.writes().len() as u64,
    }
}

/// Records a finished run from its [`WriteTimeline`]: bandwidth windows of its publications, a latency message per
/// (write, receiver) that was applied, a convergence window per write that reached every receiver, all in log-time
/// order, then the summary.
///
/// # Errors
/// The output cannot be written.
pub fn record_result<W: Write + Seek>(recorder: &mut RunRecorder<W>, result: &RunResult) -> anyhow::Result<()> {
    #[derive(PartialEq, Eq, PartialOrd, Ord)]
    enum Event {
        Publish(usize),
        Apply(usize, usize),
        Converged(usize, u64),
    }
    let timeline = &result.timeline;
    let receivers = timeline.receivers() as usize;
    let mut events: Vec<(u64, Event)> = Vec::with_capacity(timeline.writes().len() * (receivers + 2));
    for (seq, write) in timeline.writes().iter().enumerate() {
        events.push((write.publish_ns, Event::Publish(seq)));
        let mut last = Some(write.publish_ns);
        for receiver in 0..receivers {
            let applied = timeline.applied_ns(seq, receiver);
            if let Some(at) = applied {
                events.push((at, Event::Apply(seq, receiver)));
            }
            last = last.zip(applied).map(|(a, b)| a.max(b));
        }
        if let Some(at) = last.filter(|_| receivers > 0) {
            events.push((at, Event::Converged(seq, at)));
        }
    }
    events.sort_unstable();
    let mut end_ns = 0;
    for (at, event) in events {
        end_ns = at;
        match event {
            Event::Publish(seq) => recorder.published(at, timeline.writes()[seq].bytes)?,
            Event::Apply(seq, receiver) => {
                let write = timeline.writes()[seq];
                recorder.latency(&WriteLatency {
                    seq: seq as u64,
                    class: write.class,
                    receiver: receiver as u32 + 1,
                    publish_ns: write.publish_ns,
                    apply_ns: at,
                    latency_ns: at.saturating_sub(write.publish_ns),
                    bytes: write.bytes,
                })?;
            }
            Event::Converged(seq, converged_ns) => {
                let write = timeline.writes()[seq];
                recorder.convergence(&ConvergenceWindow {
                    seq: seq as u64,
                    class: write.class,
                    publish_ns: write.publish_ns,
                    converged_ns,
                    window_ns: converged_ns.saturating_sub(write.publish_ns).max(1),
                    receivers: receivers as u32,
                })?;
            }
        }
    }
    recorder.summary(end_ns, &summary_of(result))
}

/// One file written by [`write_runs`].
#[derive(Clone, Debug)]
pub struct RecordedRun {
    /// Path relative to the report's directory (`runs/…mcap`).
    pub path: PathBuf,
    /// What the run was (`replay`, `payload` or `faults`, and the run's label).
    pub label: String,
    /// Messages written, per topic.
    pub counts: RecordCounts,
}

fn slug(text: &str) -> String {
    let mut out = String::new();
    for c in text.replace(".mcap", "").chars() {
        if c.is_ascii_alphanumeric() || c == '.' {
            out.push(c.to_ascii_lowercase());
        } else if !out.ends_with('-') {
            out.push('-');
        }
    }
    out.trim_matches('-').chars().take(80).collect()
}

/// Writes one MCAP file per run of `results` into `out/runs/`: its summary, per-write latencies, convergence
/// windows and bandwidth windows, with the set's provenance as metadata.
///
/// # Errors
/// A file that cannot be written.
pub fn write_runs(results: &Results, out: &Path) -> anyhow::Result<Vec<RecordedRun>> {
    let dir = out.join("runs");
    std::fs::create_dir_all(&dir).with_context(|| format!("cannot create {}", dir.display()))?;
    let mut runs: Vec<(String, String, &RunResult)> = Vec::new();
    for (i, run) in results.replay.iter().enumerate() {
        let label = format!("{} {} N={} seed {}", run.workload, run.transport, run.agents, run.seed);
        runs.push((format!("replay-{i:02}"), label, run));
    }
    for (i, run) in results.payload.iter().enumerate() {
        runs.push((format!("payload-{i:02}"), format!("{} N={}", run.workload, run.agents), run));
    }
    for (i, fault) in results.faults.iter().enumerate() {
        runs.push((format!("faults-{i:02}"), format!("{} ({})", fault.label, fault.run.workload), &fault.run));
    }
    let mut recorded = Vec::new();
    for (kind, label, run) in runs {
        let path = PathBuf::from("runs").join(format!("{kind}-{}.mcap", slug(&label)));
        let mut metadata = provenance_metadata(&results.provenance);
        metadata.insert("experiment".to_owned(), format!("{} ({})", results.experiment, results.mode));
        metadata.insert("run".to_owned(), format!("{kind}: {label}"));
        let mut recorder = RunRecorder::create(&out.join(&path), metadata)?;
        record_result(&mut recorder, run).with_context(|| format!("cannot record {}", path.display()))?;
        let counts = finish_file(recorder).with_context(|| format!("cannot finish {}", path.display()))?;
        recorded.push(RecordedRun { path, label: format!("{kind}: {label}"), counts });
    }
    Ok(recorded)
}

struct InFlight {
    publish_ns: u64,
    class: PayloadClass,
    bytes: u64,
    remaining: usize,
    window_ns: u64,
}

/// What a [`RecordingSink`] measured, for the run's summary.
#[derive(Debug)]
pub struct LiveStats {
    /// Latency of every (delta, receiver) pair.
    pub latency: LatencyRecorder,
    /// Per-delta convergence windows.
    pub convergence: Histogram<u64>,
    /// Deltas published.
    pub writes: u64,
    /// Bytes of their encodings.
    pub published_bytes: u64,
    /// Deltas some receiver had not applied when the recording ended.
    pub writes_not_everywhere: u64,
    /// Last publication, ns on the run's clock.
    pub last_publish_ns: u64,
    /// Last application anywhere, ns on the run's clock.
    pub last_apply_ns: u64,
}

/// A [`Sink`] around an [`InProcNetwork`] that records the run as it happens: each delta when it is published (its
/// encoded bytes, on the delta channel), then each application at a receiver (a latency message), and a
/// convergence window when the last receiver has applied it. Times come from `clock`; the payload class of the
/// deltas is read from `class` when they are published (the caller sets it per message).
///
/// Memory: the deltas in flight (bounded by the network's window plus one message's deltas) and two histograms.
pub struct RecordingSink<'a, W: Write + Seek> {
    network: &'a mut InProcNetwork,
    recorder: RunRecorder<W>,
    clock: MonoClock,
    class: &'a Cell<PayloadClass>,
    deliveries: Receiver<(Delivery, u64)>,
    in_flight: BTreeMap<u64, InFlight>,
    stats: LiveStats,
}

impl<'a, W: Write + Seek> RecordingSink<'a, W> {
    /// Records what `network` delivers into `recorder` (which gets a delta channel for `dictionary`); installs
    /// the network's delivery hook.
    ///
    /// # Errors
    /// The output cannot be written.
    pub fn new(
        network: &'a mut InProcNetwork,
        mut recorder: RunRecorder<W>,
        dictionary: &str,
        clock: MonoClock,
        class: &'a Cell<PayloadClass>,
    ) -> anyhow::Result<Self> {
        recorder.add_delta_channel(dictionary)?;
        let (sender, deliveries) = channel();
        // Drained after every publish and flush, so it holds at most one call's deliveries.
        network.on_delivery(move |delivery| {
            let _ = sender.send((delivery, clock.now_ns()));
        });
        let stats = LiveStats {
            latency: LatencyRecorder::new(),
            convergence: latency::histogram(),
            writes: 0,
            published_bytes: 0,
            writes_not_everywhere: 0,
            last_publish_ns: 0,
            last_apply_ns: 0,
        };
        Ok(RecordingSink { network, recorder, clock, class, deliveries, in_flight: BTreeMap::new(), stats })
    }

    fn drain(&mut self) -> anyhow::Result<()> {
        let receivers = self.network.receivers().len();
        while let Ok((delivery, apply_ns)) = self.deliveries.try_recv() {
            let flight = self.in_flight.get_mut(&delivery.index).context("a delivery of an unknown delta")?;
            let latency_ns = apply_ns.saturating_sub(flight.publish_ns);
            flight.remaining -= 1;
            flight.window_ns = flight.window_ns.max(latency_ns);
            let (class, publish_ns, bytes) = (flight.class, flight.publish_ns, flight.bytes);
            self.stats.latency.record(class, latency_ns);
            self.stats.last_apply_ns = self.stats.last_apply_ns.max(apply_ns);
            self.recorder.latency(&WriteLatency {
                seq: delivery.index,
                class,
                receiver: delivery.receiver as u32 + 1,
                publish_ns,
                apply_ns,
                latency_ns,
                bytes,
            })?;
            if flight.remaining == 0 {
                let window_ns = flight.window_ns.max(1);
                self.in_flight.remove(&delivery.index);
                self.stats.convergence.saturating_record(window_ns);
                self.recorder.convergence(&ConvergenceWindow {
                    seq: delivery.index,
                    class,
                    publish_ns,
                    converged_ns: apply_ns,
                    window_ns,
                    receivers: receivers as u32,
                })?;
            }
        }
        Ok(())
    }

    /// Ends the recording's live part: returns the recorder (to add the summary and finish it) and what was measured.
    pub fn finish(self) -> (RunRecorder<W>, LiveStats) {
        let mut stats = self.stats;
        stats.writes_not_everywhere = self.in_flight.len() as u64;
        (self.recorder, stats)
    }
}

fn recording_failed(error: anyhow::Error) -> SinkError {
    SinkError::Transport(format!("cannot record the run: {error:#}"))
}

impl<W: Write + Seek> Sink for RecordingSink<'_, W> {
    fn publish(&mut self, deltas: &[Arc<Delta>]) -> Result<(), SinkError> {
        let first = self.network.stats().deltas;
        let publish_ns = self.clock.now_ns();
        let class = self.class.get();
        let receivers = self.network.receivers().len();
        for (i, delta) in deltas.iter().enumerate() {
            let index = first + i as u64;
            let bytes = delta.encode();
            self.recorder.delta(index, publish_ns, &bytes).map_err(recording_failed)?;
            self.stats.writes += 1;
            self.stats.published_bytes += bytes.len() as u64;
            self.stats.last_publish_ns = publish_ns;
            if receivers > 0 {
                let flight =
                    InFlight { publish_ns, class, bytes: bytes.len() as u64, remaining: receivers, window_ns: 0 };
                self.in_flight.insert(index, flight);
            }
        }
        let published = self.network.publish(deltas);
        self.drain().map_err(recording_failed)?;
        published
    }

    fn flush(&mut self) -> Result<(), SinkError> {
        let flushed = self.network.flush();
        self.drain().map_err(recording_failed)?;
        flushed
    }
}

#[cfg(test)]
mod tests {
    use std::io::Cursor;

    use bytes::Bytes;
    use dsr::{Replica, ReplicaId};
    use replay::log::{Log, ReadOptions};
    use replay::{Bridge, BridgeOptions, Pacer, Rate};

    use super::*;
    use crate::run::{self, RunConfig};
    use crate::workload;

    /// Whether `value` has the structure `schema` describes: types, enums, required and unexpected keys, nested
    /// objects and arrays (the subset of JSON Schema our schemas use).
    fn conforms(value: &Json, schema: &Json, at: &str) -> Result<(), String> {
        let type_ok = |name: &str| match name {
            "object" => value.is_object(),
            "array" => value.is_array(),
            "string" => value.is_string(),
            "integer" => value.is_u64() || value.is_i64(),
            "number" => value.is_number(),
            "boolean" => value.is_boolean(),
            "null" => value.is_null(),
            other => panic!("unknown type {other} in a schema"),
        };
        let types: Vec<&str> = match &schema["type"] {
            Json::String(t) => vec![t.as_str()],
            Json::Array(ts) => ts.iter().filter_map(Json::as_str).collect(),
            other => return Err(format!("{at}: schema without a type: {other}")),
        };
        if !types.iter().any(|t| type_ok(t)) {
            return Err(format!("{at}: {value} is not of type {types:?}"));
        }
        if let Some(min) = schema["minimum"].as_f64()
            && value.as_f64().is_some_and(|v| v < min)
        {
            return Err(format!("{at}: {value} below {min}"));
        }
        if let Some(allowed) = schema["enum"].as_array()
            && !allowed.contains(value)
        {
            return Err(format!("{at}: {value} not in {allowed:?}"));
        }
        if let (Some(object), Some(properties)) = (value.as_object(), schema["properties"].as_object()) {
            for key in schema["required"].as_array().into_iter().flatten() {
                let key = key.as_str().unwrap();
                if !object.contains_key(key) {
                    return Err(format!("{at}: required `{key}` missing"));
                }
            }
            for (key, item) in object {
                match properties.get(key) {
                    Some(property) => conforms(item, property, &format!("{at}.{key}"))?,
                    None if schema["additionalProperties"] == false => {
                        return Err(format!("{at}: `{key}` is not in the schema"));
                    }
                    None => {}
                }
            }
        } else if let (Some(object), Some(each)) = (value.as_object(), schema["additionalProperties"].as_object()) {
            for (key, item) in object {
                conforms(item, &Json::Object(each.clone()), &format!("{at}.{key}"))?;
            }
        }
        if let (Some(items), Some(each)) = (value.as_array(), schema.get("items")) {
            for (i, item) in items.iter().enumerate() {
                conforms(item, each, &format!("{at}[{i}]"))?;
            }
        }
        Ok(())
    }

    /// Reads `bytes` with both readers and checks what every recording must be; returns the messages per topic as
    /// the project's reader sees them (payloads as JSON where the channel is JSON).
    fn check_recording(bytes: &[u8]) -> BTreeMap<String, Vec<(u64, Bytes)>> {
        // The `mcap` crate: an indexed file whose summary agrees with its messages.
        let summary = mcap::Summary::read(bytes).unwrap().expect("a summary section");
        let stats = summary.stats.clone().expect("statistics");
        assert!(!summary.chunk_indexes.is_empty(), "chunk indexes");
        assert!(summary.chunk_indexes.iter().all(|c| !c.message_index_offsets.is_empty()), "no chunk without messages");
        assert_eq!(summary.metadata_indexes.len(), 1);
        let metadata = mcap::read::metadata(bytes, &summary.metadata_indexes[0]).unwrap();
        assert_eq!(metadata.name, RUN_METADATA);
        assert!(metadata.metadata.contains_key("commit") && metadata.metadata.contains_key("clock"));
        let mut last = 0;
        let mut per_channel: BTreeMap<u16, u64> = BTreeMap::new();
        for message in mcap::MessageStream::new(bytes).unwrap() {
            let message = message.unwrap();
            assert!(message.log_time >= last, "log times never decrease");
            last = message.log_time;
            *per_channel.entry(message.channel.id).or_insert(0) += 1;
            if message.channel.message_encoding == "json" {
                let schema = message.channel.schema.as_ref().expect("a JSON channel has a schema");
                assert_eq!(schema.encoding, "jsonschema");
                let schema: Json = serde_json::from_slice(&schema.data).expect("the schema is JSON");
                let value: Json = serde_json::from_slice(&message.data).expect("the message is JSON");
                conforms(&value, &schema, &message.channel.topic).unwrap();
            } else {
                assert_eq!(message.channel.topic, DELTA_TOPIC);
                assert_eq!(message.channel.message_encoding, DELTA_MESSAGE_ENCODING);
            }
        }
        assert_eq!(per_channel, stats.channel_message_counts);
        assert_eq!(stats.message_count, per_channel.values().sum::<u64>());
        assert_eq!(stats.message_end_time, last);

        // The project's own reader: the same channels and messages.
        let log = Log::from_bytes("recording", Bytes::copy_from_slice(bytes), ReadOptions::default()).unwrap();
        assert!(log.damage.is_none());
        assert_eq!(log.messages.len() as u64, stats.message_count);
        for metric in Metric::ALL {
            let channel = log.channels.values().find(|c| c.topic == metric.topic()).expect("every metric channel");
            assert_eq!((channel.type_name(), channel.message_encoding.as_str()), (metric.schema_name(), "json"));
            let schema: Json = serde_json::from_slice(&channel.schema.as_ref().unwrap().data).unwrap();
            assert_eq!(schema, metric.schema());
            assert_eq!(schema["type"], "object");
            assert_eq!(schema["required"].as_array().unwrap().len(), schema["properties"].as_object().unwrap().len());
        }
        let mut topics: BTreeMap<String, Vec<(u64, Bytes)>> = BTreeMap::new();
        for message in &log.messages {
            topics.entry(message.channel.topic.clone()).or_default().push((message.log_time, message.data.clone()));
        }
        topics
    }

    fn json_of<T: serde::de::DeserializeOwned>(messages: &[(u64, Bytes)]) -> Vec<T> {
        messages.iter().map(|(_, data)| serde_json::from_slice(data).unwrap()).collect()
    }

    #[test]
    fn a_measured_run_records_every_latency_and_reads_back_with_both_readers() {
        let workload = workload::synthetic(300, 2000.0, 40, 3).unwrap();
        let result = run::run(&workload, &RunConfig { agents: 4, ..RunConfig::default() }).unwrap();
        assert_eq!(result.timeline.writes().len(), 41);
        let mut recorder = RunRecorder::new(
            Cursor::new(Vec::new()),
            BTreeMap::from([("commit".to_owned(), "test".to_owned()), ("clock".to_owned(), "test".to_owned())]),
        )
        .unwrap();
        record_result(&mut recorder, &result).unwrap();
        let (out, counts) = recorder.finish().unwrap();
        let topics = check_recording(out.get_ref());

        let latencies: Vec<WriteLatency> = json_of(&topics["/metrics/latency"]);
        assert_eq!(latencies.len(), 41 * 3);
        assert_eq!(counts[Metric::Latency.topic()], 41 * 3);
        for sample in &latencies {
            assert_eq!(sample.latency_ns, sample.apply_ns - sample.publish_ns);
            assert!((1..=3).contains(&sample.receiver));
            assert_eq!(sample.bytes, 8 + workload.writes[sample.seq as usize].delta.len() as u64);
        }
        let mut pairs: Vec<(u64, u32)> = latencies.iter().map(|s| (s.seq, s.receiver)).collect();
        pairs.sort_unstable();
        pairs.dedup();
        assert_eq!(pairs.len(), 41 * 3, "one message per (write, receiver)");
        let windows: Vec<ConvergenceWindow> = json_of(&topics["/metrics/convergence"]);
        assert_eq!(windows.len(), 41);
        for window in &windows {
            let slowest = latencies.iter().filter(|s| s.seq == window.seq).map(|s| s.latency_ns).max().unwrap();
            assert_eq!(window.window_ns, slowest.max(1));
        }
        let bandwidth: Vec<BandwidthSample> = json_of(&topics["/metrics/bandwidth"]);
        assert_eq!(bandwidth.iter().map(|b| b.writes).sum::<u64>(), 41);
        assert_eq!(bandwidth.iter().map(|b| b.bytes).sum::<u64>(), result.sample_bytes);
        assert!(bandwidth.windows(2).all(|w| w[1].window_start_ns == w[0].window_start_ns + BANDWIDTH_WINDOW_NS));
        let summaries: Vec<RunSummary> = json_of(&topics["/metrics/summary"]);
        assert_eq!(summaries, vec![summary_of(&result)]);
        assert_eq!(summaries[0].latency.count, 41 * 3);
        assert!(!topics.contains_key(DELTA_TOPIC), "a report run records no deltas");
    }

    #[test]
    fn recorded_deltas_rebuild_the_graph_of_a_replay() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../datasets/logs/sick_tim7xx_scan_10s.mcap");
        let log = Log::open(path, ReadOptions::default()).unwrap();
        let dictionary = replay::bridge::dictionary().unwrap();
        let mut replica = Replica::with_dictionary(ReplicaId(1), dictionary.clone());
        let mut network = InProcNetwork::new(2, 2, &dictionary, 9, 16);
        let mut bridge = Bridge::new(BridgeOptions::default());
        let clock = MonoClock::start();
        let class = Cell::new(PayloadClass::Small);
        let messages = &log.messages[..60];
        let paced = Pacer::new(messages, Rate::Max, 1, || 0)
            .inspect(|item| class.set(PayloadClass::of_schema(item.message.channel.type_name())));
        let recorder = RunRecorder::new(
            Cursor::new(Vec::new()),
            BTreeMap::from([("commit".to_owned(), "test".to_owned()), ("clock".to_owned(), "test".to_owned())]),
        )
        .unwrap();
        let mut sink = RecordingSink::new(&mut network, recorder, "bridge", clock, &class).unwrap();
        let driven = replay::inproc::drive(paced, &mut bridge, &mut replica, &mut sink, |_| {}).unwrap();
        let (mut recorder, live) = sink.finish();
        assert_eq!((live.writes, live.writes_not_everywhere), (driven.deltas, 0));
        let summary = RunSummary {
            run: "sick".into(),
            transport: "inproc".into(),
            agents: 3,
            seed: 9,
            writes: live.writes,
            published_bytes: live.published_bytes,
            latency: live.latency.overall(),
            latency_by_class: BTreeMap::new(),
            convergence: Percentiles::of(&live.convergence),
            writes_not_everywhere: 0,
            end_convergence_ns: None,
            digests_equal: true,
            digests: vec![replica.digest().to_string()],
            writes_recorded: live.writes,
        };
        recorder.summary(clock.now_ns(), &summary).unwrap();
        let (out, _) = recorder.finish().unwrap();
        let topics = check_recording(out.get_ref());

        let deltas = &topics[DELTA_TOPIC];
        assert_eq!(deltas.len() as u64, driven.deltas);
        let mut rebuilt = Replica::with_dictionary(ReplicaId(7), dictionary);
        for (_, bytes) in deltas {
            rebuilt.apply(&Delta::decode(bytes).unwrap()).unwrap();
        }
        assert_eq!(rebuilt.digest(), replica.digest());
        let latencies: Vec<WriteLatency> = json_of(&topics["/metrics/latency"]);
        assert_eq!(latencies.len() as u64, driven.deltas * 2);
        assert!(latencies.iter().any(|s| s.class == PayloadClass::Scan));
        assert!(latencies.iter().any(|s| s.class == PayloadClass::PointCloud));
        let windows: Vec<ConvergenceWindow> = json_of(&topics["/metrics/convergence"]);
        assert_eq!(windows.len() as u64, driven.deltas);
        assert!(windows.iter().all(|w| w.receivers == 2 && w.converged_ns >= w.publish_ns));
        let bandwidth: Vec<BandwidthSample> = json_of(&topics["/metrics/bandwidth"]);
        assert_eq!(bandwidth.iter().map(|b| b.bytes).sum::<u64>(), live.published_bytes);
    }

    #[test]
    fn the_structural_check_catches_messages_that_break_their_schema() {
        let schema = Metric::Latency.schema();
        let sample = WriteLatency {
            seq: 1,
            class: PayloadClass::Image,
            receiver: 1,
            publish_ns: 10,
            apply_ns: 15,
            latency_ns: 5,
            bytes: 100,
        };
        let good = serde_json::to_value(&sample).unwrap();
        conforms(&good, &schema, "m").unwrap();
        let broken = |change: &dyn Fn(&mut serde_json::Map<String, Json>)| {
            let mut value = good.clone();
            change(value.as_object_mut().unwrap());
            conforms(&value, &schema, "m").unwrap_err()
        };
        assert!(broken(&|m| drop(m.remove("seq"))).contains("required `seq`"));
        assert!(broken(&|m| drop(m.insert("extra".into(), json!(1)))).contains("not in the schema"));
        assert!(broken(&|m| drop(m.insert("class".into(), json!("video")))).contains("not in"));
        assert!(broken(&|m| drop(m.insert("latency_ns".into(), json!("5")))).contains("not of type"));
        let summary = Metric::Summary.schema();
        let mut value = serde_json::to_value(RunSummary {
            run: "r".into(),
            transport: "inproc".into(),
            agents: 2,
            seed: 1,
            writes: 0,
            published_bytes: 0,
            latency: Percentiles::default(),
            latency_by_class: BTreeMap::from([("image".to_owned(), Percentiles::default())]),
            convergence: Percentiles::default(),
            writes_not_everywhere: 0,
            end_convergence_ns: None,
            digests_equal: true,
            digests: vec!["ab".into()],
            writes_recorded: 0,
        })
        .unwrap();
        conforms(&value, &summary, "s").unwrap();
        value["latency_by_class"]["image"]["p50_ns"] = json!(-1);
        assert!(conforms(&value, &summary, "s").unwrap_err().contains("s.latency_by_class.image.p50_ns"));
    }

    #[test]
    fn a_message_older_than_the_last_is_refused() {
        let mut recorder = RunRecorder::new(Cursor::new(Vec::new()), BTreeMap::new()).unwrap();
        recorder.published(5_000, 10).unwrap();
        let error = recorder.published(4_000, 10).unwrap_err();
        assert!(error.to_string().contains("never decrease"), "{error}");
        assert!(recorder.delta(0, 6_000, b"x").unwrap_err().to_string().contains("no delta channel"));
    }

    #[test]
    fn file_names_are_plain_and_bounded() {
        assert_eq!(slug("sick_tim7xx_scan_10s.mcap inproc N=3 seed 7"), "sick-tim7xx-scan-10s-inproc-n-3-seed-7");
        assert_eq!(slug("synthetic 16 B @ 200 Hz N=3"), "synthetic-16-b-200-hz-n-3");
        assert_eq!(slug(&"x".repeat(200)).len(), 80);
    }

    #[test]
    fn a_timeline_keeps_a_bounded_number_of_writes() {
        let mut timeline = WriteTimeline::new(2);
        let write = TimelineWrite { class: PayloadClass::Small, bytes: 10, publish_ns: 1 };
        for i in 0..MAX_TIMELINE_WRITES as u64 + 5 {
            timeline.push(write, [Some(i + 2), None]);
        }
        assert_eq!(timeline.writes().len(), MAX_TIMELINE_WRITES);
        assert_eq!(timeline.not_kept(), 5);
        assert_eq!((timeline.applied_ns(3, 0), timeline.applied_ns(3, 1)), (Some(5), None));
    }
}
