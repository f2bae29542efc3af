//! One generation of DDS entities: the participants, and every topic, writer and reader in them, as the transport
//! creates them at start and the receiving thread creates them again at every rebuild (see the parent module's
//! documentation, "Recovery").

use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use crossbeam_channel::RecvTimeoutError;

use rustdds::policy::Reliability;
use rustdds::{DomainParticipant, DomainParticipantBuilder, QosPolicies, RTPSEntity, Topic, TopicKind};

use super::discovery::{DiscoveryState, DiscoveryWatch, Prefix, endpoint_of, prefix_of};
use super::engine::{EngineThread, EngineWatch};
use super::payload::{OctetsAdapter, Payload, Reader, Writer};
use super::settings::{
    RtpsConfig, best_effort_max_bytes, channel_qos, large_qos, qos, qos_with, routable_ipv4_addresses, writer_qos,
};
use crate::{Channel, EndpointId, TransportError};

/// The participants of one generation of DDS entities.
pub(super) struct Participants {
    pub(super) _publishing: DomainParticipant,
    /// The readers' own participant (see [`RtpsTransport::new`]); `None` only when neither
    /// `separate_reader_participant` nor multicast asks for it.
    pub(super) _subscribing: Option<DomainParticipant>,
}

/// A full set of DDS entities, as [`Generation::build`] makes them: at start, and at every rebuild.
/// Fields drop in order: the writers and readers before the participants.
pub(super) struct Generation {
    /// One writer per channel (by [`Channel::index`]); `None` for a channel a read-only transport does not write.
    pub(super) writers: Vec<Option<Writer>>,
    pub(super) best_effort: Option<Writer>,
    /// The writer of large updates; `None` for a read-only transport.
    pub(super) large: Option<Writer>,
    pub(super) reading: Reading,
    pub(super) local: EndpointId,
    pub(super) reading_prefix: Prefix,
    pub(super) participants: Participants,
}

/// What the receiving thread owns of a generation.
pub(super) struct Reading {
    pub(super) readers: Vec<(Channel, Reader)>,
    /// The reader of large updates (see [`super::large`]).
    pub(super) large: Reader,
    pub(super) watch: DiscoveryWatch,
    /// The endpoint id of this generation's writers: samples from it are this transport's own.
    pub(super) local: EndpointId,
    /// The threads `rustdds` runs for this generation's participants (empty where they cannot be watched).
    pub(super) engine: Vec<EngineThread>,
}

fn setup(what: impl Into<String>) -> impl FnOnce(rustdds::dds::CreateError) -> TransportError {
    let what = what.into();
    move |e| TransportError::Setup { what, detail: format!("{e:?}") }
}

impl Generation {
    /// Joins the DDS domain with new participants and creates every topic, writer and reader in them (see
    /// [`RtpsTransport::new`]); `state` is where the new readers' discovery events are recorded.
    ///
    /// The build runs on a thread of its own, which this one waits for. A stop and resume of the process while
    /// `rustdds` hands a new writer or reader to its participant's event loop ends that thread and deadlocks the
    /// hand-over (see `build_here`); a build that has not ended [`DEADLOCKED_AFTER`] after one of its participants'
    /// threads did is given up as [`TransportError::EngineEnded`], and its thread and participants are left behind
    /// (silent: their event loop has ended). One that has not ended after [`GIVE_UP_AFTER`] is given up too (stuck
    /// before its threads could be watched); should it end after all, what it built is dropped.
    pub(super) fn build(
        config: &RtpsConfig,
        multicast: bool,
        state: &Arc<DiscoveryState>,
    ) -> Result<Generation, TransportError> {
        let (sender, built) = crossbeam_channel::bounded(1);
        let seen = Arc::new(Mutex::new(Vec::new()));
        let (config, state, seen_there) = (config.clone(), Arc::clone(state), Arc::clone(&seen));
        std::thread::Builder::new()
            .name("rtps-build".into())
            .spawn(move || {
                let _ = sender.send(Generation::build_here(&config, multicast, &state, &seen_there));
            })
            .map_err(|e| TransportError::Setup { what: "the RTPS build thread".into(), detail: e.to_string() })?;
        let (started, mut ended) = (Instant::now(), None::<(String, Instant)>);
        loop {
            match built.recv_timeout(BUILD_LOOK_PERIOD) {
                Ok(result) => return result,
                Err(RecvTimeoutError::Disconnected) => {
                    return Err(TransportError::Setup { what: "the RTPS build".into(), detail: "it panicked".into() });
                }
                Err(RecvTimeoutError::Timeout) => {}
            }
            let threads = seen.lock().unwrap_or_else(|p| p.into_inner());
            match (&ended, threads.iter().find(|thread| !thread.alive())) {
                (None, Some(thread)) => ended = Some((format!("{:?}", thread.name), Instant::now())),
                (Some((thread, at)), _) if at.elapsed() >= DEADLOCKED_AFTER => {
                    tracing::error!(
                        "rtps: the transport's build is stuck in rustdds since its thread {thread} ended (a \
                         SIGSTOP/SIGCONT during the build); giving it up, and leaving its thread and participants \
                         behind"
                    );
                    return Err(TransportError::EngineEnded { thread: thread.clone() });
                }
                _ if started.elapsed() >= GIVE_UP_AFTER => {
                    tracing::error!(
                        "rtps: the transport's build has not ended after {GIVE_UP_AFTER:?} (stuck in rustdds, whose \
                         threads ended before they could be watched?); giving it up"
                    );
                    return Err(TransportError::Setup {
                        what: "the RTPS build".into(),
                        detail: format!("no result after {GIVE_UP_AFTER:?}"),
                    });
                }
                _ => {}
            }
        }
    }

    /// [`Generation::build`]'s work, on the calling thread; the new participants' `rustdds` threads are put in
    /// `seen` as soon as they are known.
    fn build_here(
        config: &RtpsConfig,
        multicast: bool,
        state: &Arc<DiscoveryState>,
        seen: &Mutex<Vec<EngineThread>>,
    ) -> Result<Generation, TransportError> {
        let (publishing, subscribing, engine) = join_domain(config, multicast)?;
        seen.lock().unwrap_or_else(|p| p.into_inner()).clone_from(&engine);
        // Every writer and reader is handed to its participant's event loop. If that thread has ended (a SIGSTOP
        // and SIGCONT during the build end it), rustdds 0.15 fails the hand-over and then, dropping the new entity
        // while it still holds the publisher's or subscriber's lock, deadlocks. So the build looks at the engine's
        // threads before each creation and gives up as soon as one has ended; the caller builds again. A stop that
        // lands inside a creation still deadlocks it: `build` gives such a build up.
        let running = || match engine.iter().find(|thread| !thread.alive()) {
            Some(thread) => Err(TransportError::EngineEnded { thread: format!("{:?}", thread.name) }),
            None => Ok(()),
        };
        let qos = qos(config);
        let publisher = publishing.create_publisher(&qos).map_err(setup("publisher"))?;
        let subscriber =
            subscribing.as_ref().unwrap_or(&publishing).create_subscriber(&qos).map_err(setup("subscriber"))?;
        let mut writers = Vec::new();
        let mut readers = Vec::new();
        let mut endpoints = Vec::new();
        // The topic of `name` in the publishing participant, and in the subscribing one (the same if none).
        let topics = |name: &str, qos: &QosPolicies| -> Result<(Topic, Topic), TransportError> {
            let topic = |participant: &DomainParticipant| {
                participant
                    .create_topic(name.to_owned(), "cortex::Envelope".into(), qos, TopicKind::NoKey)
                    .map_err(setup(format!("topic {name}")))
            };
            let written = topic(&publishing)?;
            let read = match &subscribing {
                Some(participant) => topic(participant)?,
                None => written.clone(),
            };
            Ok((written, read))
        };
        // A writer's QoS is its topic's with a keep-last history and its own send window (`writer_qos`).
        let writer = |topic: &Topic, name: &str, qos: &QosPolicies| {
            running()?;
            publisher
                .create_datawriter_no_key::<Payload, OctetsAdapter>(topic, Some(writer_qos(config, qos)))
                .map_err(setup(format!("writer of {name}")))
        };
        let reader = |topic: &Topic, name: &str, qos: &QosPolicies| {
            running()?;
            subscriber
                .create_simple_datareader_no_key::<Payload, OctetsAdapter>(topic, Some(qos.clone()))
                .map_err(setup(format!("reader of {name}")))
        };
        for channel in Channel::ALL {
            let name = format!("{}_{}", config.topic_prefix, channel.name());
            let qos = channel_qos(config, channel);
            let (written, read) = topics(&name, &qos)?;
            let reader = reader(&read, &name, &qos)?;
            // A read-only transport writes requests alone (its permissions may grant nothing else).
            let writer = if config.read_only && channel != Channel::Requests {
                None
            } else {
                let writer = writer(&written, &name, &qos)?;
                endpoints.push((channel, Some(writer.guid()), reader.guid()));
                Some(writer)
            };
            if writer.is_none() {
                endpoints.push((channel, None, reader.guid()));
            }
            writers.push(writer);
            readers.push((channel, reader));
        }
        // Every transport reads the best-effort updates topic, so agents of one graph may mix settings; only a
        // transport set to best-effort writes on it.
        let best_effort = {
            let name = format!("{}_updates_be", config.topic_prefix);
            let qos = qos_with(config, Reliability::BestEffort);
            let (written, read) = topics(&name, &qos)?;
            let reader = reader(&read, &name, &qos)?;
            let writer = match best_effort_max_bytes(config) {
                None => None,
                Some(_) => {
                    let writer = writer(&written, &name, &qos)?;
                    endpoints.push((Channel::Updates, Some(writer.guid()), reader.guid()));
                    Some(writer)
                }
            };
            readers.push((Channel::Updates, reader));
            writer
        };
        // Large updates: a topic with a small cache of its own (see `super::large`). Its endpoints are not watched:
        // discovery is followed on the updates topic, and no write on it is directed.
        let (large, large_reader) = {
            let name = format!("{}_updates_large", config.topic_prefix);
            let qos = large_qos(config);
            let (written, read) = topics(&name, &qos)?;
            let writer = if config.read_only { None } else { Some(writer(&written, &name, &qos)?) };
            (writer, reader(&read, &name, &qos)?)
        };
        // Samples are tagged with their writer's GUID prefix: the publishing participant's.
        let local = endpoint_of(publishing.guid());
        // Discovery events of both participants: the writers' matches come from the publishing one, the readers'
        // from the subscribing one.
        let mut statuses = vec![publishing.status_listener()];
        statuses.extend(subscribing.as_ref().map(DomainParticipant::status_listener));
        let reading_prefix = prefix_of(subscribing.as_ref().unwrap_or(&publishing).guid());
        let own = vec![prefix_of(publishing.guid()), reading_prefix];
        let watch = DiscoveryWatch { statuses, own, endpoints, state: Arc::clone(state) };
        Ok(Generation {
            writers,
            best_effort,
            large,
            local,
            reading_prefix,
            participants: Participants { _publishing: publishing, _subscribing: subscribing },
            reading: Reading { readers, large: large_reader, watch, local, engine },
        })
    }
}

/// How long a build may go on after one of its participants' `rustdds` threads has ended before it is taken for
/// deadlocked ([`Generation::build`]): a build whose engine has ended fails or finishes within microseconds.
const DEADLOCKED_AFTER: Duration = Duration::from_secs(2);
/// How long a build may take at all before it is given up ([`Generation::build`]): a build takes well under a
/// second, and `rustdds` itself gives up waiting for a new participant's discovery thread after 10 s.
const GIVE_UP_AFTER: Duration = Duration::from_secs(30);
/// How often the waiting thread looks at the build's `rustdds` threads.
const BUILD_LOOK_PERIOD: Duration = Duration::from_millis(50);

/// Builds attempted at start ([`Generation::first`]).
const FIRST_BUILD_ATTEMPTS: u32 = 5;

impl Generation {
    /// The first generation, at the transport's start. A build that fails is tried again with new participants, at
    /// most [`FIRST_BUILD_ATTEMPTS`] times in all: a stop and resume of the process during a build ends `rustdds`'s
    /// threads, which fails it in many ways ([`TransportError::EngineEnded`], a participant whose discovery thread
    /// could not start, a build given up), and nothing but building again tells those from a lasting cause, which
    /// then fails every attempt alike. (Later builds are the receiving thread's rebuilds, which retry any failure.)
    pub(super) fn first(
        config: &RtpsConfig,
        multicast: bool,
        state: &Arc<DiscoveryState>,
    ) -> Result<Generation, TransportError> {
        let mut attempt = 1;
        loop {
            match Generation::build(config, multicast, state) {
                Err(error) if attempt < FIRST_BUILD_ATTEMPTS => {
                    tracing::warn!(
                        "rtps: building the transport failed (attempt {attempt} of {FIRST_BUILD_ATTEMPTS}): {error}; \
                         building it again with new participants"
                    );
                    attempt += 1;
                }
                built => return built,
            }
        }
    }
}

/// Creates this generation's participants (the subscribing one only when the readers live apart, see
/// [`RtpsConfig::separate_reader_participant`]), and finds the threads `rustdds` started for them.
fn join_domain(
    config: &RtpsConfig,
    multicast: bool,
) -> Result<(DomainParticipant, Option<DomainParticipant>, Vec<EngineThread>), TransportError> {
    let networks = if multicast { routable_ipv4_addresses() } else { None };
    let join = |role: &str| {
        let mut builder = DomainParticipantBuilder::new(config.domain_id).same_host_loopback(!multicast);
        if let Some(addresses) = networks.clone() {
            builder = builder.with_only_networks(addresses);
        }
        if let Some(files) = &config.security {
            builder = secured(builder, files)?;
        }
        builder.build().map_err(|e| TransportError::Setup {
            what: format!("{role} participant in domain {}", config.domain_id),
            detail: format!("{e:?}"),
        })
    };
    let (created, watch) = EngineWatch::create(|| -> Result<_, TransportError> {
        let publishing = join("publishing")?;
        // Multicast needs the readers apart too: rustdds never routes a writer to its own participant's
        // readers, and their fallback path would send a second copy.
        let subscribing =
            if config.separate_reader_participant || multicast { Some(join("subscribing")?) } else { None };
        Ok((publishing, subscribing))
    });
    let (publishing, subscribing) = created?;
    let engine = watch.into_threads();
    let participants = 1 + usize::from(subscribing.is_some());
    if engine.len() < 2 * participants && EngineThread::watchable() {
        // Threads are watched here, yet some of the new participants' threads were gone before they could be seen
        // (a stop and resume while the participants were being created).
        return Err(TransportError::EngineEnded {
            thread: format!("{} of the {} new threads", 2 * participants - engine.len(), 2 * participants),
        });
    }
    if engine.len() != 2 * participants {
        tracing::warn!(
            "rtps: found {} rustdds threads for {participants} new participant(s), expected {}: a participant \
             whose threads end may go unnoticed (no /proc/self/task, or participants created elsewhere in this \
             process at the same time)",
            engine.len(),
            2 * participants
        );
    }
    Ok((publishing, subscribing, engine))
}

/// `builder` with DDS Security's builtin plugins configured from `files`.
#[cfg(feature = "security")]
fn secured(
    builder: DomainParticipantBuilder,
    files: &super::settings::SecurityFiles,
) -> Result<DomainParticipantBuilder, TransportError> {
    if let Some(missing) = super::settings::SecurityFiles::FILES.iter().find(|name| !files.dir.join(name).is_file()) {
        return Err(TransportError::Setup {
            what: format!("DDS Security credentials in {}", files.dir.display()),
            detail: format!("{missing} is missing"),
        });
    }
    // The key is not encrypted; rustdds asks for a password all the same.
    let configuration =
        rustdds::DomainParticipantSecurityConfigFiles::with_ros_default_names(&files.dir, "unencrypted".into());
    Ok(builder.builtin_security(configuration))
}

/// Without the `security` feature, credentials are refused with a clear error.
#[cfg(not(feature = "security"))]
fn secured(
    _builder: DomainParticipantBuilder,
    files: &super::settings::SecurityFiles,
) -> Result<DomainParticipantBuilder, TransportError> {
    Err(TransportError::Setup {
        what: format!("DDS Security with the credentials in {}", files.dir.display()),
        detail: "this build of the transport has no DDS Security (cargo feature `security`)".into(),
    })
}

#[cfg(test)]
mod tests {
    use std::time::{Duration, Instant};

    use super::*;

    #[test]
    fn the_threads_of_new_participants_are_found_and_their_end_is_seen() {
        if !EngineThread::watchable() {
            return; // Not Linux: nothing to watch.
        }
        let config = RtpsConfig { domain_id: 94, topic_prefix: "engine_threads".into(), ..RtpsConfig::default() };
        let generation = Generation::build(&config, false, &Arc::new(DiscoveryState::default())).unwrap();
        let threads = generation.reading.engine.clone();
        // Two participants, each with its event loop and its discovery thread.
        assert_eq!(threads.len(), 4, "{threads:?}");
        assert_eq!(threads.iter().filter(|t| t.name.starts_with("RustDDS Partici")).count(), 2, "{threads:?}");
        assert!(threads.iter().all(EngineThread::alive));
        drop(generation);
        let deadline = Instant::now() + Duration::from_secs(5);
        while threads.iter().any(EngineThread::alive) {
            assert!(Instant::now() < deadline, "threads still running after their participants were dropped");
            std::thread::sleep(Duration::from_millis(10));
        }
    }

    #[test]
    fn every_reader_caches_what_its_channel_is_given() {
        let config = RtpsConfig {
            domain_id: 94,
            topic_prefix: "reader_caches".into(),
            reader_cache_samples: 55,
            sync_cache_samples: 7,
            large_cache_samples: 9,
            ..RtpsConfig::default()
        };
        let generation = Generation::build(&config, false, &Arc::new(DiscoveryState::default())).unwrap();
        let cache = |reader: &Reader| reader.qos().resource_limits().map(|limits| limits.max_samples);
        for (channel, reader) in &generation.reading.readers {
            let expected = if *channel == Channel::Sync { 7 } else { 55 };
            assert_eq!(cache(reader), Some(expected), "the reader of {}", channel.name());
        }
        assert_eq!(cache(&generation.reading.large), Some(9), "the reader of large updates");
    }
}
