//! How an agent is driven: by threads of its own ([`Agent::start`]), or by hand — by its application's thread,
//! which calls [`Agent::pump_wait`] in a loop of its own, or by a simulation on a manual clock, which calls
//! [`Agent::pump`] (it never waits). Every way, a sample goes through the same handling and the periodic work
//! through the same tick; only the thread differs.
//!
//! A started agent handles samples on the transport's receiving thread (RTPS) or on its own (shared memory), and a
//! change callback runs there; an application's thread that waits for the change is woken from that thread. An
//! application that drives its agent receives on the thread that writes: a reply to its write wakes that thread,
//! with no hand-off between two threads of one process (on two cores, the second thread often sleeps on the other,
//! idle core, and a virtual CPU's wake-up from idle is slow).

use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::Duration;

use transport::{Channel, Clock, Transport};

use super::{Agent, AgentConfig, AgentError, Inner, timer};
use crate::core::{Dest, Send};

/// The agent's thread's longest wait while joining (it looks at discovery for a new match each time).
const JOINING_TICK: Duration = Duration::from_millis(2);

/// Samples handled in one turn of a driving loop, before it looks at the periodic work.
const BATCH: usize = 1024;

impl<T: Transport + 'static> Agent<T> {
    /// An agent that runs on its own: samples are handled as they arrive — on the transport's receiving thread
    /// where the transport offers one ([`Transport::set_sink`], RTPS does), else on the agent's own thread — and
    /// the agent's thread does the periodic work (announces, join retries) when it is due; a third thread publishes
    /// call replies as they come. An idle agent sleeps: its thread wakes when the protocol core's next deadline
    /// comes (the next announce, or the quiet announce after a write; rounded up to [`AgentConfig::tick`], at most
    /// 1 s apart), and the replies thread only for a reply. `clock` must advance in real time, since the threads
    /// sleep until its deadlines.
    ///
    /// # Errors
    /// As [`Agent::new`], and [`AgentError::Thread`].
    pub fn start(config: AgentConfig, transport: T, clock: Arc<dyn Clock>) -> Result<Self, AgentError> {
        let agent = Agent::new(config, transport, clock)?;
        // Where the transport can, samples are handled on its receiving thread as they arrive: one thread hand-off
        // less per sample than through the agent's thread, which then only does the periodic work (and handles what
        // was queued before). The sink holds the agent's state; `shutdown` clears it.
        let inner = Arc::clone(&agent.inner);
        let sink: transport::Sink = Arc::new(move |sample| inner.handle(sample));
        let has_sink = agent.inner.transport.set_sink(Some(sink));
        let inner = Arc::clone(&agent.inner);
        agent.spawn("", move || inner.run(has_sink))?;
        // Publishes the call replies of this agent's server as they come (the server never does I/O itself).
        let inner = Arc::clone(&agent.inner);
        agent.spawn("-replies", move || inner.publish_replies())?;
        Ok(agent)
    }

    /// Starts a thread named after this agent and `suffix`, joined by [`Agent::shutdown`].
    fn spawn(&self, suffix: &str, body: impl FnOnce() + std::marker::Send + 'static) -> Result<(), AgentError> {
        let agent = self.inner.config.id;
        let handle = std::thread::Builder::new()
            .name(format!("agent-{}{suffix}", agent.0))
            .spawn(body)
            .map_err(|e| AgentError::Thread { agent, detail: e.to_string() })?;
        self.threads.lock().unwrap_or_else(|p| p.into_inner()).push(handle);
        Ok(())
    }

    /// Handles every sample waiting on the transport, then does the periodic work due. Returns the samples
    /// handled. (For agents made with [`Agent::new`].)
    pub fn pump(&self) -> usize {
        let mut handled = 0;
        while let Some(sample) = self.inner.transport.try_recv() {
            self.inner.handle(sample);
            handled += 1;
        }
        self.inner.tick();
        self.flush_call_replies();
        handled
    }

    /// Drives the agent from the calling thread, for an application with a loop of its own (an agent made with
    /// [`Agent::new`]): waits for a sample until the agent's periodic work is due, at most `timeout`, handles it and
    /// what is queued behind it, does the periodic work if due and publishes the call replies ready. Returns the
    /// samples handled; it returns early when the periodic work comes due or a local write moves it earlier, so
    /// call it in a loop, at least every [`AgentConfig::tick`] while the agent is to keep up with the others. On an
    /// agent started with threads of its own ([`Agent::start`]) it only sleeps for `timeout` and returns 0: those
    /// threads handle the samples.
    ///
    /// Change callbacks then run on this thread, the one that writes: an answer to a write wakes the thread that
    /// wrote, which on a same-host round trip saves a hand-off between the agent's thread and the application's.
    ///
    /// ```
    /// use std::sync::Arc;
    /// use std::time::{Duration, Instant};
    ///
    /// use agent::{Agent, AgentConfig, AgentId};
    /// use dsr::NewNode;
    /// use transport::SystemClock;
    /// use transport::inproc::Bus;
    ///
    /// let bus = Bus::new();
    /// let config = |id, join_wait| AgentConfig { join_wait, ..AgentConfig::new(AgentId(id)) };
    /// // A peer with threads of its own starts the graph.
    /// let peer = Agent::start(config(2, Duration::from_millis(20)), bus.attach(1024), Arc::new(SystemClock))?;
    /// assert!(peer.wait_ready(Duration::from_secs(10)));
    /// let cup = peer.insert_node(NewNode::new("object", "cup"))?;
    /// // This application's agent joins it, driven by the application's one thread.
    /// let agent = Agent::new(config(1, Duration::from_secs(10)), bus.attach(1024), Arc::new(SystemClock))?;
    /// let deadline = Instant::now() + Duration::from_secs(10);
    /// while agent.node(cup).is_none() && Instant::now() < deadline {
    ///     // ... the application's own work for this turn, then the agent's:
    ///     agent.pump_wait(Duration::from_millis(10));
    /// }
    /// assert_eq!(agent.node(cup).map(|n| n.name).as_deref(), Some("cup"));
    /// # Ok::<(), agent::AgentError>(())
    /// ```
    pub fn pump_wait(&self, timeout: Duration) -> usize {
        // A started agent's own thread waits on the transport (holding its wait for up to a second): a second
        // receiver would wait behind it, past `timeout`. Its threads do the work; this only waits.
        if !self.threads.lock().unwrap_or_else(|p| p.into_inner()).is_empty() {
            std::thread::sleep(timeout);
            return 0;
        }
        let handled = self.inner.serve_once(timeout, false);
        self.flush_call_replies();
        handled
    }

    /// Publishes the call replies this agent's server has produced so far (the threaded agent does this on its
    /// own; an agent driven by hand does it in [`Agent::pump`] and [`Agent::pump_wait`]). Returns how many.
    pub fn flush_call_replies(&self) -> usize {
        if self.inner.service.outbox_rx.is_empty() {
            return 0;
        }
        let graph = self.inner.lock().core.graph();
        let replies: Vec<Send> = self
            .inner
            .service
            .outbox_rx
            .try_iter()
            .map(|message| Send { channel: Channel::Calls, message, dest: Dest::All, graph, sample: None })
            .collect();
        let n = replies.len();
        self.inner.send(replies, None);
        n
    }
}

impl<T: Transport + 'static> Inner<T> {
    /// The agent's own thread: sleeps until the periodic work is due (or, without a sink, until a sample arrives),
    /// handles what is queued on the transport, does the work.
    fn run(&self, has_sink: bool) {
        // With a sink the thread sleeps on the timer's bell, which writes ring; without one it waits on the
        // transport, which writes interrupt where it can ([`Transport::interrupt`]), and else wakes every tick.
        let longest = if has_sink || self.transport.interrupt() { timer::IDLE_LONGEST } else { self.config.tick() };
        while !self.stop.load(Ordering::Relaxed) {
            self.serve_once(longest, has_sink);
        }
    }

    /// One turn of a loop that drives the agent: waits until the periodic work is due, at most `longest` (at most
    /// [`JOINING_TICK`] while joining), for a sample on the transport or, with a sink (which handles the samples),
    /// for the timer's bell; handles the sample that came and those queued behind it (at most [`BATCH`]), then the
    /// periodic work if it is due. Returns the samples handled.
    fn serve_once(&self, longest: Duration, has_sink: bool) -> usize {
        // While joining, look often: a graph request goes out as soon as discovery matches a peer.
        let longest = if self.joined.load(Ordering::Relaxed) { longest } else { longest.min(JOINING_TICK) };
        let wait = self.timer.wait_at(self.clock.now_ns(), longest);
        let first = if has_sink {
            self.timer.sleep(wait);
            self.transport.try_recv()
        } else {
            self.transport.recv_timeout(wait)
        };
        let mut handled = 0;
        if let Some(sample) = first {
            self.handle(sample);
            handled = 1;
            // What came behind it, with no wait: a transport may look only where it was told samples came, which
            // costs less than `try_recv`'s look at everything (shared memory).
            while handled < BATCH {
                let Some(sample) = self.transport.recv_timeout(Duration::ZERO) else { break };
                self.handle(sample);
                handled += 1;
            }
        }
        // Woken before the deadline (rung, a sample): nothing periodic to do yet. While joining, every look
        // also checks discovery for a new match.
        if !self.joined.load(Ordering::Relaxed) || self.timer.is_due(self.clock.now_ns()) {
            self.tick();
        }
        handled
    }

    /// The replies thread: publishes each call reply of this agent's server as it comes, until halted.
    fn publish_replies(&self) {
        loop {
            crossbeam_channel::select! {
                recv(self.service.outbox_rx) -> reply => {
                    let Ok(message) = reply else { return };
                    let graph = self.lock().core.graph();
                    self.send(vec![Send { channel: Channel::Calls, message, dest: Dest::All, graph, sample: None }], None);
                }
                recv(self.halt.1) -> _ => return,
            }
        }
    }
}
