//! [`Ros2Bridge`]: the bridge's DDS side on the ROS 2 domain — one `rustdds` participant, a reader per input topic
//! and a writer per output topic, with ROS 2's topic names, type names and QoS — and its two threads (In:
//! `reader`, Out: `writer`) over an [`Agent`] of the graph.

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::Duration;

use agent::Agent;
use rustdds::{DomainParticipant, DomainParticipantBuilder, Publisher, Subscriber, TopicKind};
use transport::rtps::EngineWatch;

use crate::config::{BridgeConfig, dds_topic, dds_type};
use crate::inbound::Inbound;
use crate::lock;
use crate::qos::QosProfile;
use crate::raw::{RawCdrAdapter, RawWriter};
use crate::reader::{InReader, InShared, read_loop};
use crate::status::{BridgeStatus, InLatency, Latencies, OutCounters};
use crate::writer::{OutKind, OutShared, Output, write_loop};

/// Change signals the Out thread may have pending before the agent drops new ones (the thread only needs to be
/// woken, and it reads the current graph).
const SIGNAL_CAPACITY: usize = 1024;

/// The bridge could not start.
#[derive(Debug, thiserror::Error)]
#[error("ros2 bridge: {what}: {detail}")]
pub struct StartError {
    /// What was being created (`participant in ROS 2 domain 7`, `reader of rt/scan`).
    pub what: String,
    /// The DDS error.
    pub detail: String,
}

fn setup<E: std::fmt::Debug>(what: impl Into<String>) -> impl FnOnce(E) -> StartError {
    let what = what.into();
    move |error| StartError { what, detail: format!("{error:?}") }
}

/// A running bridge. Dropping it (or [`Ros2Bridge::stop`]) stops its threads, then leaves the ROS 2 domain.
///
/// **Recovery.** `rustdds` 0.15's own threads end for good when the process is resumed after a stop signal (see
/// `transport::rtps`, "Recovery"), which leaves a participant deaf and mute. A supervisor thread watches the
/// participant's threads ([`EngineWatch`]) and, when one has ended, stops the In and Out threads, drops the
/// participant and builds a new one with all its readers and writers (a failed rebuild is tried again a second
/// later); the counters and latencies carry over, `rebuilds` in the status counts it. ROS 2 peers discover the
/// new participant like a new node; a reader of `/tf_static` gets the static transforms again from the new writer.
pub struct Ros2Bridge {
    stop: Arc<AtomicBool>,
    supervisor: Option<JoinHandle<()>>,
    inputs: Arc<InShared>,
    outputs: Arc<OutShared>,
    rebuilds: Arc<AtomicU64>,
}

/// How often the supervisor looks at `rustdds`'s threads.
const WATCH_INTERVAL: Duration = Duration::from_millis(200);
/// The least time between two rebuilds.
const REBUILD_INTERVAL: Duration = Duration::from_secs(1);

/// One participant with its readers, writers and the In and Out threads over them.
struct Generation {
    stop: Arc<AtomicBool>,
    threads: Vec<JoinHandle<()>>,
    engine: EngineWatch,
    _participant: DomainParticipant,
}

impl Generation {
    /// Joins the domain and starts the threads; `inputs` and `outputs` are the counters they add to.
    fn start<T: transport::Transport + 'static>(
        config: &BridgeConfig,
        agent: &Arc<Agent<T>>,
        inputs: &Arc<InShared>,
        outputs: &Arc<OutShared>,
    ) -> Result<Generation, StartError> {
        let (participant, engine) = EngineWatch::create(|| DomainParticipantBuilder::new(config.ros_domain).build());
        let participant = participant.map_err(setup(format!("participant in ROS 2 domain {}", config.ros_domain)))?;
        let qos = QosProfile::Default.policies();
        let subscriber = participant.create_subscriber(&qos).map_err(setup("subscriber"))?;
        let publisher = participant.create_publisher(&qos).map_err(setup("publisher"))?;
        let readers = create_readers(config, &participant, &subscriber)?;
        let (writers, counters) = create_outputs(config, &participant, &publisher)?;
        {
            // The first generation sets the counters; later ones keep what was counted.
            let mut kept = lock(&outputs.counters);
            if kept.is_empty() {
                *kept = counters;
            }
        }
        let stop = Arc::new(AtomicBool::new(false));
        let mut threads = Vec::new();
        if !readers.is_empty() {
            let (agent, shared, stop) = (Arc::clone(agent), Arc::clone(inputs), Arc::clone(&stop));
            threads.push(spawn("ros2-bridge-in", move || read_loop(&agent, readers, &shared, &stop))?);
        }
        if !writers.is_empty() {
            let signals = agent.subscribe(SIGNAL_CAPACITY);
            let (agent, shared, stop) = (Arc::clone(agent), Arc::clone(outputs), Arc::clone(&stop));
            threads.push(spawn("ros2-bridge-out", move || write_loop(&agent, writers, &signals, &shared, &stop))?);
        }
        Ok(Generation { stop, threads, engine, _participant: participant })
    }

    /// Stops the threads and waits for them; the participant goes with `self`.
    fn stop(mut self) {
        self.stop.store(true, Ordering::SeqCst);
        for thread in self.threads.drain(..) {
            if thread.join().is_err() {
                tracing::error!("ros2 bridge: a thread panicked");
            }
        }
    }
}

impl Ros2Bridge {
    /// Joins `config.ros_domain` and starts bridging between it and `agent`'s graph (the agent should have its
    /// graph: writes before that are refused and counted).
    ///
    /// # Errors
    /// [`StartError`] if the domain cannot be joined or an entity cannot be created.
    pub fn start<T: transport::Transport + 'static>(
        config: &BridgeConfig,
        agent: Arc<Agent<T>>,
    ) -> Result<Ros2Bridge, StartError> {
        let inputs = Arc::new(InShared {
            inbound: Mutex::new(Inbound::new(&config.inputs)),
            latencies: Mutex::new(vec![(Latencies::default(), Latencies::default()); config.inputs.len()]),
        });
        let outputs = Arc::new(OutShared::default());
        let generation = Generation::start(config, &agent, &inputs, &outputs)?;
        if generation.engine.threads() == 0 {
            tracing::warn!("ros2 bridge: rustdds's threads cannot be watched here (no /proc/self/task): no recovery");
        }
        let stop = Arc::new(AtomicBool::new(false));
        let rebuilds = Arc::new(AtomicU64::new(0));
        let supervisor = {
            let (config, inputs, outputs) = (config.clone(), Arc::clone(&inputs), Arc::clone(&outputs));
            let (stop, rebuilds) = (Arc::clone(&stop), Arc::clone(&rebuilds));
            spawn("ros2-bridge-watch", move || {
                supervise(generation, &config, &agent, &inputs, &outputs, &stop, &rebuilds);
            })?
        };
        Ok(Ros2Bridge { stop, supervisor: Some(supervisor), inputs, outputs, rebuilds })
    }

    /// The counters and latency summaries so far.
    pub fn status(&self) -> BridgeStatus {
        let (counters, decoded, tf_refused, deltas) = {
            let inbound = lock(&self.inputs.inbound);
            let stats = inbound.bridge_stats();
            (inbound.counters(), stats.decoded.clone(), stats.tf_refused, stats.deltas)
        };
        let latency_in = {
            let latencies = lock(&self.inputs.latencies);
            counters
                .iter()
                .zip(latencies.iter())
                .map(|(topic, (taken, in_graph))| InLatency {
                    topic: topic.topic.clone(),
                    taken: taken.summary(),
                    in_graph: in_graph.summary(),
                })
                .collect()
        };
        BridgeStatus {
            inputs: counters,
            outputs: lock(&self.outputs.counters).clone(),
            decoded,
            tf_refused,
            deltas,
            bad_rt_edges: *lock(&self.outputs.bad_rt_edges),
            latency_in,
            latency_out: lock(&self.outputs.latency).summary(),
            rebuilds: self.rebuilds.load(Ordering::Relaxed),
        }
    }

    /// Stops the threads and waits for them.
    pub fn stop(mut self) {
        self.stop_threads();
    }

    fn stop_threads(&mut self) {
        self.stop.store(true, Ordering::SeqCst);
        if let Some(supervisor) = self.supervisor.take()
            && supervisor.join().is_err()
        {
            tracing::error!("ros2 bridge: the supervisor panicked");
        }
    }
}

impl Drop for Ros2Bridge {
    fn drop(&mut self) {
        self.stop_threads();
    }
}

/// Watches the generation's `rustdds` threads until `stop`, rebuilding it when one has ended; stops it at the end.
fn supervise<T: transport::Transport + 'static>(
    mut generation: Generation,
    config: &BridgeConfig,
    agent: &Arc<Agent<T>>,
    inputs: &Arc<InShared>,
    outputs: &Arc<OutShared>,
    stop: &AtomicBool,
    rebuilds: &AtomicU64,
) {
    while !stop.load(Ordering::SeqCst) {
        std::thread::sleep(WATCH_INTERVAL);
        let Some(ended) = generation.engine.ended().map(str::to_owned) else { continue };
        tracing::error!("ros2 bridge: rustdds's thread {ended:?} has ended (a stop signal?): rebuilding the DDS side");
        generation.stop();
        generation = loop {
            match Generation::start(config, agent, inputs, outputs) {
                Ok(next) => break next,
                Err(error) if !stop.load(Ordering::SeqCst) => {
                    tracing::error!("ros2 bridge: rebuild failed, trying again: {error}");
                    std::thread::sleep(REBUILD_INTERVAL);
                }
                Err(_) => return,
            }
        };
        let n = rebuilds.fetch_add(1, Ordering::Relaxed) + 1;
        tracing::warn!("ros2 bridge: DDS side rebuilt (rebuild {n}); ROS 2 peers discover it anew");
        std::thread::sleep(REBUILD_INTERVAL);
    }
    generation.stop();
}

fn spawn(name: &str, body: impl FnOnce() + Send + 'static) -> Result<JoinHandle<()>, StartError> {
    std::thread::Builder::new().name(name.into()).spawn(body).map_err(setup(format!("thread {name}")))
}

fn create_readers(
    config: &BridgeConfig,
    participant: &DomainParticipant,
    subscriber: &Subscriber,
) -> Result<Vec<InReader>, StartError> {
    let mut readers = Vec::new();
    for (index, input) in config.inputs.iter().enumerate() {
        let (name, qos) = (dds_topic(&input.topic), input.qos.policies());
        let topic = participant
            .create_topic(name.clone(), dds_type(&input.type_name), &qos, TopicKind::NoKey)
            .map_err(setup(format!("topic {name}")))?;
        let reader = subscriber
            .create_simple_datareader_no_key::<crate::raw::RawCdr, RawCdrAdapter>(&topic, Some(qos))
            .map_err(setup(format!("reader of {name}")))?;
        let stamped = input.type_name != "tf2_msgs/msg/TFMessage";
        readers.push(InReader { index, reader, stamped });
    }
    Ok(readers)
}

fn create_outputs(
    config: &BridgeConfig,
    participant: &DomainParticipant,
    publisher: &Publisher,
) -> Result<(Vec<Output>, Vec<OutCounters>), StartError> {
    let writer = |topic: &str, type_name: &str, qos: QosProfile| -> Result<RawWriter, StartError> {
        let (name, qos) = (dds_topic(topic), qos.policies());
        let dds_topic = participant
            .create_topic(name.clone(), dds_type(type_name), &qos, TopicKind::NoKey)
            .map_err(setup(format!("topic {name}")))?;
        publisher
            .create_datawriter_no_key::<crate::raw::RawCdr, RawCdrAdapter>(&dds_topic, Some(qos))
            .map_err(setup(format!("writer of {name}")))
    };
    let interval = |rate_hz: f64| Duration::from_secs_f64(1.0 / rate_hz);
    let mut outputs = Vec::new();
    let mut counters = Vec::new();
    let mut add = |kind: OutKind, writer: RawWriter, min_interval: Duration, counter: OutCounters| {
        outputs.push(Output { kind, writer, min_interval, last_sent: None, last_dot: None });
        counters.push(counter);
    };
    let counter = |topic: &str, kind: &'static str, node: Option<&str>| OutCounters {
        topic: topic.into(),
        kind,
        node: node.map(str::to_owned),
        ..OutCounters::default()
    };
    const TF: &str = "tf2_msgs/msg/TFMessage";
    if let Some(tf) = &config.tf_out {
        let static_frames = tf.static_frames.clone();
        add(
            OutKind::Tf(tf.clone()),
            writer("/tf", TF, QosProfile::Default)?,
            interval(tf.rate_hz),
            counter("/tf", "tf", None),
        );
        add(
            OutKind::TfStatic { static_frames, last: None },
            writer("/tf_static", TF, QosProfile::Static)?,
            interval(tf.rate_hz),
            counter("/tf_static", "tf_static", None),
        );
    }
    for out in &config.image_out {
        let w = writer(&out.topic, "sensor_msgs/msg/Image", out.qos)?;
        add(OutKind::Image(out.clone()), w, interval(out.rate_hz), counter(&out.topic, "image", Some(&out.node)));
    }
    for out in &config.laser_out {
        let w = writer(&out.topic, "sensor_msgs/msg/LaserScan", out.qos)?;
        add(OutKind::Laser(out.clone()), w, interval(out.rate_hz), counter(&out.topic, "laser", Some(&out.node)));
    }
    Ok((outputs, counters))
}
