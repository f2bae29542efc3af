//! The agent paths: an agent in this process writes `cam_rgb` of the node `payload_source`; each receiver process
//! runs an agent over the same [`Link`], stamps every change signal of that attribute in its replica, and answers
//! the samples that ask for it by writing the sample's number into `cam_rgb` of its own node `payload_rx<I>`. The
//! samples are numbered as [`super::numbering`] says.

use std::path::Path;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use agent::rtps::AgentTransport;
use agent::{Agent, AgentConfig, AgentId, Link};
use anyhow::{Context as _, bail};
use bytes::Bytes;
use dsr::{Change, Element, NewNode, NodeId, attrs};
use transport::rtps::RtpsConfig;
use transport::{Clock as _, SystemClock};

use super::numbering::{self, Heard, NumberedWriter, Stamps};
use super::{Counting, ReceiverReport, spawn_receivers};
use crate::bench::{helper, payload_of, seq_of};
use crate::results::PayloadCell;
use crate::spec::{PayloadPath, PayloadPathsExperiment};

const SOURCE: &str = "payload_source";

fn receiver_node(index: u32) -> String {
    format!("payload_rx{index}")
}

fn config(id: u32, join_wait: Duration) -> AgentConfig {
    let mut config = AgentConfig::new(AgentId(id));
    config.join_wait = join_wait;
    config
}

fn rtps(domain: u16, prefix: &str) -> RtpsConfig {
    RtpsConfig { domain_id: domain, topic_prefix: prefix.into(), ..RtpsConfig::default() }
}

/// The writer of a session and what it has written.
struct Writer {
    agent: Arc<Agent<AgentTransport>>,
    source: NodeId,
    receivers: u32,
    next: u64,
}

impl NumberedWriter for Writer {
    fn next_number(&mut self) -> u64 {
        self.next += 1;
        self.next - 1
    }

    fn send(&mut self, value: Bytes) -> anyhow::Result<()> {
        Ok(self.agent.set_attr(self.source, attrs::CAM_RGB, value)?)
    }

    fn answered(&self, at_least: u64) -> bool {
        (0..self.receivers).all(|i| {
            let node = self.agent.node_by_name(&receiver_node(i));
            let answer = node.and_then(|n| self.agent.attr(n.id, attrs::CAM_RGB)).and_then(|b| seq_of(&b));
            answer.is_some_and(|n| n >= at_least)
        })
    }
}

/// Which session of agents: over which link, to how many receivers, on which DDS domain, and which start of it.
#[derive(Clone, Copy, Debug)]
pub(super) struct Session {
    /// The agents' link.
    pub(super) link: Link,
    /// Receiver processes.
    pub(super) receivers: u32,
    /// DDS domain of agents over RTPS.
    pub(super) domain: u16,
    /// 1 for the session's first start, 2 for the next ([`crate::restart::with_restarts`]): each start has topics
    /// of its own.
    pub(super) start: u32,
}

/// Every size of `experiment` from an agent here to agents in `session.receivers` processes of `program`.
pub(super) fn session(
    experiment: &PayloadPathsExperiment,
    session: &Session,
    counting: &Counting,
    program: &Path,
    progress: &mut dyn FnMut(&str),
) -> anyhow::Result<Vec<PayloadCell>> {
    let Session { link, receivers, domain, start } = *session;
    let path = PayloadPath::Agents(link);
    let prefix = format!("payload{}{}n{receivers}s{start}", std::process::id(), link.name());
    let agent = link.start(config(1, Duration::from_millis(300)), rtps(domain, &prefix), None)?;
    if !agent.wait_ready(Duration::from_secs(10)) {
        bail!("the writing agent did not start");
    }
    let source = agent.insert_node(NewNode::new("object", SOURCE))?;
    let mut writer = Writer { agent, source, receivers, next: 0 };
    let (helpers, pids) =
        spawn_receivers(program, receivers, |i| helper::payload_receiver_args(link.name(), domain, &prefix, i))?;
    let label = format!("agents over {link}");
    let cells = numbering::measure(&mut writer, path, &label, experiment, (helpers, &pids), counting, progress);
    writer.agent.shutdown();
    cells
}

/// A receiver process of an agent path: an agent of the graph on `domain` and `prefix` over `link` that stamps
/// every new value of the source's `cam_rgb` in a change callback (on the thread that joined it, as raw iceoryx2's
/// receivers stamp on theirs) and answers those that ask, until told to stop.
pub(super) fn receive(link: Link, domain: u16, prefix: &str, index: u32) -> anyhow::Result<ReceiverReport> {
    let agent = link.start(config(2 + index, Duration::from_secs(30)), rtps(domain, prefix), None)?;
    if !agent.wait_ready(Duration::from_secs(30)) {
        bail!("receiver {index} got no graph within 30 s");
    }
    let deadline = Instant::now() + Duration::from_secs(30);
    let source = loop {
        if let Some(node) = agent.node_by_name(SOURCE) {
            break node.id;
        }
        if Instant::now() > deadline {
            bail!("receiver {index}: the graph has no {SOURCE} node after 30 s");
        }
        std::thread::sleep(Duration::from_millis(10));
    };
    let me = agent.insert_node(NewNode::new("object", &receiver_node(index))).context("the receiver's node")?;
    let stamps = Arc::new(Mutex::new(Stamps::starting_at(SystemClock.now_ns())));
    let (stop, stopped) = std::sync::mpsc::sync_channel(1);
    let callback = {
        let (weak, stamps) = (Arc::downgrade(&agent), Arc::clone(&stamps));
        agent.on_change(move |signal| {
            let from_source = matches!(&signal.change, Change::AttrUpdated { element: Element::Node(id), name }
                if *id == source && name.as_str() == "cam_rgb");
            let Some(agent) = weak.upgrade().filter(|_| from_source && !signal.local) else { return };
            let at = SystemClock.now_ns();
            let Some(value) = agent.attr(source, attrs::CAM_RGB).and_then(|b| seq_of(&b)) else { return };
            // Taken under the lock, which is released before the answer: a failed answer records itself under it.
            let heard = stamps.lock().unwrap_or_else(|p| p.into_inner()).take(value, at);
            match heard {
                Heard::Stop => drop(stop.try_send(())),
                Heard::Answer(number) => {
                    if let Err(error) = agent.set_attr(me, attrs::CAM_RGB, payload_of(number, 8)) {
                        let failure = format!("receiver {index}: answering sample {number} failed: {error}");
                        stamps.lock().unwrap_or_else(|p| p.into_inner()).failure.get_or_insert(failure);
                    }
                }
                Heard::Quiet => {}
            }
        })
    };
    let outcome = wait_for_stop(&stamps, &stopped, index);
    agent.remove_on_change(callback);
    agent.shutdown();
    outcome?;
    let delivered = std::mem::take(&mut stamps.lock().unwrap_or_else(|p| p.into_inner()).delivered);
    Ok(ReceiverReport { index, delivered })
}

/// Waits for the stop value; fails when the writer has been silent for [`numbering::WRITER_SILENT`].
fn wait_for_stop(stamps: &Mutex<Stamps>, stopped: &std::sync::mpsc::Receiver<()>, index: u32) -> anyhow::Result<()> {
    loop {
        if stopped.recv_timeout(Duration::from_secs(1)).is_ok() {
            return Ok(());
        }
        let (silent, failure) = {
            let stamps = stamps.lock().unwrap_or_else(|p| p.into_inner());
            (stamps.writer_silent(SystemClock.now_ns()), stamps.failure.clone())
        };
        if let Some(failure) = failure {
            bail!(failure);
        }
        if silent {
            bail!("receiver {index}: the writer fell silent");
        }
    }
}
