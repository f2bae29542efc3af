//! `cortex replay --transport inproc`: the bridge's replica and the other agents' replicas in this process, joined
//! by the seeded in-memory delivery of `replay::inproc`; with `--out DIR`, recorded as `DIR/run.mcap`.

use std::cell::Cell;
use std::fs::File;
use std::io::BufWriter;
use std::path::PathBuf;
use std::time::Instant;

use anyhow::Context as _;
use dsr::{Replica, ReplicaId};
use measure::record::{self, LiveStats, RecordingSink, RunRecorder, RunSummary};
use measure::{MonoClock, PayloadClass, Percentiles, Provenance};
use replay::inproc::{self, InProcNetwork};
use replay::log::Log;
use replay::{Bridge, BridgeOptions, Pacer};

use super::config::Resolved;
use super::summary::{Recording, Summary, finish, summary};

/// How a replica gets the dictionary the recorded deltas need.
const BRIDGE_DICTIONARY: &str = "replay::bridge::dictionary()";

/// What `--out` is recording: the file, its recorder and what the recording sink measured.
type Live = (PathBuf, (RunRecorder<BufWriter<File>>, LiveStats));

/// Runs the in-process replay of `log` (read in `read_seconds`) and prints its summary.
///
/// # Errors
/// A delta a receiver refuses, a recording that cannot be written, or final digests that differ.
pub(super) fn run(args: &Resolved, log: &Log, read_seconds: f64) -> anyhow::Result<()> {
    let dictionary = replay::bridge::dictionary().context("bridge dictionary")?;
    let mut replica = Replica::with_dictionary(ReplicaId(1), dictionary.clone());
    let mut network = InProcNetwork::new(args.agents - 1, 2, &dictionary, args.seed, args.window);
    let mut bridge = Bridge::new(BridgeOptions { topics: args.topics.clone(), opaque: args.opaque });
    let clock = MonoClock::start();
    let pacer = Pacer::new(&log.messages, args.rate, args.loops, move || clock.now_ns());
    // The recording labels each delta with the payload class of the message it came from, set here as the message
    // is taken from the pacer, just before the bridge ingests it and publishes its deltas.
    let class = Cell::new(PayloadClass::Small);
    let paced = pacer.inspect(|item| class.set(PayloadClass::of_schema(item.message.channel.type_name())));
    let wait = |due_ns: u64| clock.sleep_until(due_ns);
    let started = Instant::now();
    let (driven, live) = match &args.out {
        None => (inproc::drive(paced, &mut bridge, &mut replica, &mut network, wait).context("replay")?, None),
        Some(dir) => {
            std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
            let path = dir.join("run.mcap");
            let recorder = RunRecorder::create(&path, metadata(args))?;
            let mut sink = RecordingSink::new(&mut network, recorder, BRIDGE_DICTIONARY, clock, &class)?;
            let driven = inproc::drive(paced, &mut bridge, &mut replica, &mut sink, wait).context("replay")?;
            (driven, Some((path, sink.finish())))
        }
    };
    let seconds = started.elapsed().as_secs_f64();
    let (digests, digests_equal) = inproc::digests(&replica, &network);
    let stats = network.stats();
    let digests: Vec<String> = digests.iter().map(ToString::to_string).collect();
    let recording = match live {
        None => None,
        Some(live) => Some(finish_recording(args, log, live, clock, &digests, digests_equal)?),
    };
    let summary = Summary {
        delta_bytes: stats.encoded_bytes,
        deliveries: stats.deliveries,
        digests,
        digests_equal,
        recording,
        ..summary(args, log, "inproc", &driven, [read_seconds, seconds], bridge.stats().clone())
    };
    finish(args, &summary)
}

/// The recording's metadata: provenance, the command, the agents and the delivery.
fn metadata(args: &Resolved) -> std::collections::BTreeMap<String, String> {
    let mut provenance = Provenance::current();
    provenance.seeds.insert("delivery".to_owned(), args.seed);
    let mut metadata = record::provenance_metadata(&provenance);
    metadata.insert("run".to_owned(), format!("cortex replay {}", args.file.display()));
    metadata.insert("agents".to_owned(), args.agents.to_string());
    metadata.insert("delivery".to_owned(), format!("in process, seed {}, window {}", args.seed, args.window));
    metadata.insert("loops".to_owned(), args.loops.to_string());
    metadata
}

/// Writes the run's summary into the recording and closes the file; what it recorded.
fn finish_recording(
    args: &Resolved,
    log: &Log,
    (path, (mut recorder, live)): Live,
    clock: MonoClock,
    digests: &[String],
    digests_equal: bool,
) -> anyhow::Result<Recording> {
    let latency = live.latency.overall();
    let convergence = Percentiles::of(&live.convergence);
    let summary = RunSummary {
        run: args.file.file_name().map_or_else(|| log.file.clone(), |n| n.to_string_lossy().into_owned()),
        transport: "inproc".to_owned(),
        agents: args.agents,
        seed: args.seed,
        writes: live.writes,
        published_bytes: live.published_bytes,
        latency,
        latency_by_class: live.latency.by_class().into_iter().map(|(c, p)| (c.name().to_owned(), p)).collect(),
        convergence,
        writes_not_everywhere: live.writes_not_everywhere,
        end_convergence_ns: digests_equal.then(|| live.last_apply_ns.saturating_sub(live.last_publish_ns)),
        digests_equal,
        digests: digests.to_vec(),
        writes_recorded: live.writes,
    };
    recorder.summary(clock.now_ns(), &summary)?;
    let messages = record::finish_file(recorder).with_context(|| format!("cannot write {}", path.display()))?;
    Ok(Recording { path: path.display().to_string(), messages, latency: Some(latency), convergence: Some(convergence) })
}
