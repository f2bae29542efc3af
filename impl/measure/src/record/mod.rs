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
//! from each [`crate::results::RunResult`]'s bounded [`crate::results::WriteTimeline`]).

use std::collections::BTreeMap;
use std::fs::File;
use std::io::{BufWriter, Seek, Write};
use std::path::Path;

use anyhow::Context as _;
use mcap::records::{MessageHeader, Metadata};
use serde::{Deserialize, Serialize};
use serde_json::{Value as Json, json};

use crate::latency::{PayloadClass, Percentiles};
use crate::provenance::Provenance;

mod runs;
mod sink;
#[cfg(test)]
mod tests;

pub use crate::results::{MAX_TIMELINE_WRITES, TimelineWrite, WriteTimeline};
pub use runs::{RecordedRun, record_result, summary_of, write_runs};
pub use sink::{LiveStats, RecordingSink};

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
