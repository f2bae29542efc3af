//! One campaign: start the agents in their namespaces, run the schedule's episodes (writers on, one fault, heal,
//! writers off, wait until every running agent shows the same graph), collect the final states and the whole
//! history of writes for [`super::check`].
//!
//! Writes are issued by the campaign, one outstanding per agent, at `write_hz` per agent, each with a draw from the
//! campaign's seeded generator; the agent chooses the operation from the draw and its own graph and answers with
//! the record. So the schedule is a function of the seed, while which agent makes which write depends on timing. An
//! agent is killed only when it has no write outstanding, so every operation that exists is in the history.

use std::collections::BTreeMap;
use std::io::Write;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{Receiver, Sender, channel};
use std::time::{Duration, Instant};

use anyhow::{Context, Result, bail};
use transport::rng::SplitMix64;

use super::net::{Filter, Network};
use super::procs::{Launch, Line, Proc, identity, log_tail};
use agent::StatusLine;
use measure::units::ms_from_duration;

use super::protocol::{Command, FinalState, Report, WriteRecord, parse_report};
use super::record::{CampaignConfig, EpisodeResult, Event, ReadyLife, Recorded, Segment, Shown};
use super::schedule::{Episode, Fault, Schedule, StopPoint};

#[derive(Debug, Default)]
struct Slot {
    proc: Option<Proc>,
    lives: u32,
    paused: bool,
    draining: bool,
    outstanding: Option<u64>,
    next_write: Option<Instant>,
    status: Option<(Instant, StatusLine)>,
    replica: Option<u32>,
    /// The other slots that had a graph, ran, were not stopped and were reachable when this life started.
    ready_peers: Vec<usize>,
    /// Its namespace is cut off from the others (a kill whose new life is isolated).
    isolated: bool,
    segments: Vec<Segment>,
    final_state: Option<FinalState>,
}

/// A campaign in progress.
pub struct Campaign {
    config: CampaignConfig,
    launch: Launch,
    network: Network,
    slots: Vec<Slot>,
    lines_tx: Sender<Line>,
    lines: Receiver<Line>,
    started: Instant,
    rng: SplitMix64,
    seq: u64,
    writing: bool,
    history: std::io::BufWriter<std::fs::File>,
    writes: Vec<WriteRecord>,
    lives: Vec<ReadyLife>,
    killed_replicas: Vec<u32>,
    skipped: u64,
    problems: Vec<String>,
    next_sample: Instant,
    interrupted: Arc<AtomicBool>,
}

/// Period of the timeline's samples.
const SAMPLE: Duration = Duration::from_millis(50);
/// How long the loop sleeps when nothing arrives.
const IDLE: Duration = Duration::from_millis(2);

impl Campaign {
    /// Builds the network and opens `dir/history.jsonl`; no agent runs yet.
    ///
    /// # Errors
    /// The network cannot be built or the directory written.
    pub fn new(
        config: CampaignConfig,
        program: PathBuf,
        dir: PathBuf,
        tag: &str,
        interrupted: Arc<AtomicBool>,
    ) -> Result<Campaign> {
        std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
        let _ = std::fs::remove_dir_all(dir.join("agents"));
        let network = Network::create(tag, config.agents, config.same_host)?;
        let history_path = dir.join("history.jsonl");
        let history = std::io::BufWriter::new(
            std::fs::File::create(&history_path).with_context(|| format!("creating {}", history_path.display()))?,
        );
        let security = if config.security {
            let pki = dir.join("pki");
            let _ = std::fs::remove_dir_all(&pki);
            let init = crate::commands::security::InitArgs {
                dir: pki.clone(),
                agents: (0..config.agents).map(identity).collect(),
                readers: Vec::new(),
                expired: Vec::new(),
                topic_prefix: "*".into(),
                protection: crate::commands::security::Protection::Encrypt,
                days: 2,
            };
            crate::commands::security::init(&init).context("making the campaign's PKI")?;
            Some(pki)
        } else {
            None
        };
        let launch = Launch {
            security,
            program,
            domain: config.domain,
            join_wait_ms: config.join_wait_ms,
            status_ms: 100,
            image_bytes: config.image_bytes,
            dir,
            unnamed: config.unnamed,
            #[cfg(feature = "mutants")]
            plant: config.plant.clone(),
        };
        let (lines_tx, lines) = channel();
        let slots = (0..config.agents).map(|_| Slot::default()).collect();
        Ok(Campaign {
            rng: SplitMix64::new(config.seed),
            config,
            launch,
            network,
            slots,
            lines_tx,
            lines,
            started: Instant::now(),
            seq: 0,
            writing: false,
            history,
            writes: Vec::new(),
            lives: Vec::new(),
            killed_replicas: Vec::new(),
            skipped: 0,
            problems: Vec::new(),
            next_sample: Instant::now(),
            interrupted,
        })
    }

    /// Milliseconds from the start of the campaign to `at`.
    fn elapsed_ms(&self, at: Instant) -> f64 {
        ms_from_duration(at.saturating_duration_since(self.started))
    }

    fn now_ms(&self) -> f64 {
        self.elapsed_ms(Instant::now())
    }

    fn log(&mut self, event: &Event) -> Result<()> {
        let line = serde_json::to_string(event)?;
        writeln!(self.history, "{line}").context("writing history.jsonl")
    }

    /// Runs `schedule` to the end and returns what was recorded.
    ///
    /// # Errors
    /// The network or a process failed, or the campaign was interrupted (Ctrl-C).
    pub fn run(mut self, schedule: &Schedule) -> Result<Recorded> {
        self.started = Instant::now();
        self.log(&Event::Campaign { config: self.config.clone(), schedule: schedule.clone() })?;
        for slot in 0..schedule.agents - 1 {
            self.start(slot)?;
        }
        // Warm-up: the first agents get their graphs (the first starts alone), then write for a while, so that
        // the faults hit a populated graph.
        self.wait_until(|c| c.running().all(|s| c.ready(s)), Duration::from_millis(self.config.settle_ms))?;
        self.writing = true;
        self.pump_for(Duration::from_millis(self.config.fault_ms))?;
        self.writing = false;
        let heal = Instant::now();
        self.converge(heal)?;
        let mut episodes = Vec::new();
        for (index, episode) in schedule.episodes.iter().enumerate() {
            let result = self.episode(index, episode)?;
            let converged = result.heal_to_converge_ms.is_some();
            episodes.push(result);
            self.history.flush()?;
            if !converged {
                // What follows would measure nothing: the verdict already fails. Stop here, with the final states.
                break;
            }
        }
        self.finish(episodes)
    }

    fn running(&self) -> impl Iterator<Item = usize> + '_ {
        (0..self.slots.len()).filter(|s| self.slots[*s].proc.is_some())
    }

    fn ready(&self, slot: usize) -> bool {
        self.slots[slot].status.as_ref().is_some_and(|(_, s)| s.ready)
    }

    fn start(&mut self, slot: usize) -> Result<()> {
        let life = self.slots[slot].lives;
        let ready_peers = if self.slots[slot].isolated {
            Vec::new()
        } else {
            self.running().filter(|&other| other != slot && self.ready(other) && !self.slots[other].paused).collect()
        };
        let proc = Proc::start(&self.launch, &self.network.namespace(slot), slot, life, self.lines_tx.clone())?;
        let s = &mut self.slots[slot];
        s.lives += 1;
        s.proc = Some(proc);
        s.status = None;
        s.replica = None;
        s.outstanding = None;
        s.draining = false;
        s.paused = false;
        s.next_write = None;
        s.ready_peers = ready_peers;
        let t_ms = self.now_ms();
        self.log(&Event::Started { t_ms, slot, life })
    }

    fn signal(&mut self, slot: usize, signal: &str) -> Result<()> {
        let t_ms = self.now_ms();
        self.log(&Event::Signal { t_ms, slot, signal: signal.to_owned() })?;
        let s = &mut self.slots[slot];
        match signal {
            "KILL" => {
                if let Some(replica) = s.replica {
                    self.killed_replicas.push(replica);
                }
                if let Some(proc) = s.proc.take() {
                    proc.kill();
                }
                s.status = None;
                s.outstanding = None;
            }
            _ => {
                if let Some(proc) = &s.proc {
                    proc.signal(signal)?;
                }
                s.paused = signal == "STOP";
            }
        }
        Ok(())
    }

    /// Cuts `slot`'s namespace off from the others when `isolated`, until the heal.
    fn isolate_if(&mut self, slot: usize, isolated: bool) -> Result<()> {
        if isolated {
            self.set_filters(&[(slot, Filter { isolated: true, ..Filter::default() })].into())?;
        }
        Ok(())
    }

    fn set_filters(&mut self, filters: &BTreeMap<usize, Filter>) -> Result<()> {
        for slot in 0..self.slots.len() {
            let filter = filters.get(&slot).cloned().unwrap_or_default();
            self.network.set_filter(slot, &filter)?;
            self.slots[slot].isolated = filter.isolated;
        }
        Ok(())
    }

    /// Kills `agent`, restarts it `down_ms` later and stops the new process at `at` for `stopped_ms`. Until it
    /// resumes, the peers' messages do not reach it (its namespace holds the domain's user traffic; discovery
    /// passes): however late this process gets to send the `SIGSTOP`, the new life is still waiting for a graph
    /// when it comes, and no answer waits in its sockets when it resumes (it must ask again, as after a stop it
    /// could not listen). Every agent in one namespace (`--same-host`) leaves nothing to hold, so there the stop's
    /// timing alone decides.
    fn stop_at_start(&mut self, agent: usize, down_ms: u64, at: StopPoint, stopped_ms: u64) -> Result<()> {
        self.drain(agent)?;
        self.signal(agent, "KILL")?;
        if !self.config.same_host {
            let hold = Filter { hold_data_of_domain: Some(self.config.domain), ..Filter::default() };
            self.set_filters(&[(agent, hold)].into())?;
        }
        self.pump_for(Duration::from_millis(down_ms))?;
        self.start(agent)?;
        let after_ms = match at {
            StopPoint::Building { after_ms } => after_ms,
            StopPoint::Joining { after_ms } => {
                // Its first status line: the agent exists and waits for a graph.
                self.wait_until(|c| c.slots[agent].status.is_some(), Duration::from_secs(30))?;
                after_ms
            }
        };
        self.pump_for(Duration::from_millis(after_ms))?;
        self.signal(agent, "STOP")?;
        self.pump_for(Duration::from_millis(stopped_ms))?;
        self.set_filters(&BTreeMap::new())?;
        self.signal(agent, "CONT")
    }

    fn episode(&mut self, index: usize, episode: &Episode) -> Result<EpisodeResult> {
        let start = Instant::now();
        let t_ms = self.elapsed_ms(start);
        self.log(&Event::Fault { t_ms, episode: index, fault: episode.fault.clone() })?;
        self.writing = true;
        let fault_for = Duration::from_millis(episode.fault_ms);
        match &episode.fault {
            Fault::Pause { agent } => self.signal(*agent, "STOP")?,
            Fault::Kill { agent, down_ms, isolated } => {
                self.isolate_if(*agent, *isolated)?;
                self.drain(*agent)?;
                self.signal(*agent, "KILL")?;
                self.pump_for(Duration::from_millis(*down_ms))?;
                self.start(*agent)?;
                // Heal only once the new life has its graph and has written for a while (alone, if isolated).
                let agent = *agent;
                self.wait_until(|c| c.ready(agent), Duration::from_millis(self.config.settle_ms))?;
                self.pump_for(fault_for / 3)?;
            }
            Fault::LateJoin { agent, isolated: false } => self.start(*agent)?,
            Fault::LateJoin { agent, isolated: true } => {
                let agent = *agent;
                self.isolate_if(agent, true)?;
                self.start(agent)?;
                // Heal only once it has started alone and has written for a while.
                self.wait_until(|c| c.ready(agent), Duration::from_millis(self.config.settle_ms))?;
                self.pump_for(fault_for / 3)?;
            }
            Fault::StopAtStart { agent, down_ms, at, stopped_ms } => {
                self.stop_at_start(*agent, *down_ms, *at, *stopped_ms)?;
                // A life that hangs in its start fails the campaign here; heal once it has its graph and has written.
                self.wait_until(|c| c.ready(*agent), Duration::from_millis(self.config.settle_ms))?;
                self.pump_for(fault_for / 3)?;
            }
            other => self.set_filters(&filters_of(other, self.slots.len()))?,
        }
        let until = start + fault_for;
        self.pump_for(until.saturating_duration_since(Instant::now()))?;
        // Heal.
        match &episode.fault {
            Fault::Pause { agent } => self.signal(*agent, "CONT")?,
            Fault::LateJoin { isolated: false, .. } => {}
            _ => self.set_filters(&BTreeMap::new())?,
        }
        self.writing = false;
        let heal = Instant::now();
        let heal_ms = self.elapsed_ms(heal);
        self.log(&Event::Heal { t_ms: heal_ms, episode: index })?;
        let (heard, converged) = self.converge(heal)?;
        let t_ms = self.now_ms();
        let (heal_to_heard_ms, heal_to_converge_ms) = (heard.map(ms_from_duration), converged.map(ms_from_duration));
        self.log(&Event::Converged { t_ms, episode: index, heal_to_heard_ms, heal_to_converge_ms })?;
        Ok(EpisodeResult {
            kind: episode.fault.kind().to_owned(),
            description: episode.fault.describe(),
            start_ms: self.elapsed_ms(start),
            heal_ms,
            heal_to_heard_ms,
            heal_to_converge_ms,
        })
    }

    /// Stops new writes to `slot` and waits for its outstanding one.
    fn drain(&mut self, slot: usize) -> Result<()> {
        self.slots[slot].draining = true;
        self.wait_until(|c| c.slots[slot].outstanding.is_none(), Duration::from_secs(10))?;
        self.slots[slot].draining = false;
        Ok(())
    }

    /// Waits until every running agent has, after `since`, reported the same graph with the same digest, and no write is
    /// outstanding. Returns the times from `since` until every running agent had heard every other one (all peers
    /// discovered) and until they agreed; `None` for what did not happen within the settle time.
    fn converge(&mut self, since: Instant) -> Result<(Option<Duration>, Option<Duration>)> {
        let deadline = since + Duration::from_millis(self.config.settle_ms);
        let mut heard = None;
        loop {
            if heard.is_none() && self.heard_since(since) {
                heard = Some(since.elapsed());
            }
            if self.agreed_since(since) {
                let agreed = since.elapsed();
                return Ok((heard.or(Some(agreed)), Some(agreed)));
            }
            if Instant::now() >= deadline {
                return Ok((heard, None));
            }
            self.pump_once()?;
        }
    }

    /// Whether every running agent has reported, after `since`, that it hears all the others.
    fn heard_since(&self, since: Instant) -> bool {
        let running = self.running().count();
        self.running().all(|slot| {
            self.slots[slot]
                .status
                .as_ref()
                .is_some_and(|(at, s)| *at >= since && s.ready && s.peers.len() + 1 >= running)
        })
    }

    /// Whether every running agent has reported, after `since`, the same graph with the same digest.
    fn agreed_since(&self, since: Instant) -> bool {
        let mut shown = None;
        for slot in self.running() {
            let s = &self.slots[slot];
            let Some((at, status)) = &s.status else { return false };
            if *at < since || !status.ready || s.outstanding.is_some() || status.digest.is_none() {
                return false;
            }
            let this = (&status.graph, &status.digest);
            if shown.is_some_and(|other| other != this) {
                return false;
            }
            shown = Some(this);
        }
        shown.is_some()
    }

    /// Pumps until `done` holds (true) or `timeout` passes (false).
    fn wait_until(&mut self, done: impl Fn(&Campaign) -> bool, timeout: Duration) -> Result<bool> {
        let deadline = Instant::now() + timeout;
        loop {
            if done(self) {
                return Ok(true);
            }
            if Instant::now() >= deadline {
                return Ok(false);
            }
            self.pump_once()?;
        }
    }

    fn pump_for(&mut self, duration: Duration) -> Result<()> {
        let until = Instant::now() + duration;
        while Instant::now() < until {
            self.pump_once()?;
        }
        Ok(())
    }

    /// Handles what arrived, issues due writes, samples the timeline.
    fn pump_once(&mut self) -> Result<()> {
        if self.interrupted.load(Ordering::SeqCst) {
            bail!("interrupted");
        }
        if let Ok(line) = self.lines.recv_timeout(IDLE) {
            self.handle(line)?;
        }
        while let Ok(line) = self.lines.try_recv() {
            self.handle(line)?;
        }
        if self.writing {
            self.issue_writes();
        }
        if Instant::now() >= self.next_sample {
            self.next_sample = Instant::now() + SAMPLE;
            self.sample();
        }
        Ok(())
    }

    fn handle(&mut self, line: Line) -> Result<()> {
        let slot = line.slot;
        // Lines of an earlier life (still buffered when it was killed) are ignored.
        if self.slots[slot].proc.as_ref().is_none_or(|p| p.life != line.life) {
            return Ok(());
        }
        let t_ms = self.elapsed_ms(line.at);
        let Some(text) = line.text else {
            let tail = log_tail(&self.launch.dir, slot);
            self.problems.push(format!("agent {slot} (life {}) exited by itself at {t_ms:.0} ms: {tail}", line.life));
            self.slots[slot].proc = None;
            return Ok(());
        };
        match parse_report(&text) {
            Ok(Report::Status(status)) => {
                let s = &mut self.slots[slot];
                if status.ready && s.replica.is_none() {
                    s.replica = status.replica;
                    let replica = status.replica.unwrap_or(0);
                    let life =
                        ReadyLife { slot, life: line.life, alone: status.alone, ready_peers: s.ready_peers.clone() };
                    self.log(&Event::Ready { t_ms, replica, life: life.clone() })?;
                    self.lives.push(life);
                }
                self.slots[slot].status = Some((line.at, status));
            }
            Ok(Report::Wrote(mut record)) => {
                record.at_ms = t_ms;
                self.slots[slot].outstanding = None;
                self.log(&Event::Write(record.clone()))?;
                self.writes.push(record);
            }
            Ok(Report::Skipped { seq, reason }) => {
                self.slots[slot].outstanding = None;
                self.skipped += 1;
                self.log(&Event::Skipped { t_ms, slot, seq, reason })?;
            }
            Ok(Report::Final(state)) => self.slots[slot].final_state = Some(state),
            Err(error) => self.problems.push(format!("agent {slot}: {error}")),
        }
        Ok(())
    }

    fn issue_writes(&mut self) {
        let now = Instant::now();
        let period = Duration::from_secs_f64(1.0 / self.config.write_hz.max(0.01));
        for slot in 0..self.slots.len() {
            let ready = self.ready(slot);
            let s = &mut self.slots[slot];
            if s.proc.is_none() || s.paused || s.draining || s.outstanding.is_some() || !ready {
                continue;
            }
            let due = *s.next_write.get_or_insert(now);
            if now < due {
                continue;
            }
            self.seq += 1;
            let command = Command::Write { seq: self.seq, draw: self.rng.next_u64() };
            let s = &mut self.slots[slot];
            s.next_write = Some(due.max(now - period) + period);
            s.outstanding = Some(self.seq);
            if let Some(proc) = s.proc.as_mut() {
                proc.send(&command);
            }
        }
    }

    fn sample(&mut self) {
        let mut counts: BTreeMap<(Option<agent::GraphId>, &str), usize> = BTreeMap::new();
        let mut shown_by = 0;
        for slot in self.running() {
            if let Some((_, status)) = &self.slots[slot].status
                && status.ready
                && !self.slots[slot].paused
                && let Some(digest) = &status.digest
            {
                *counts.entry((status.graph, digest)).or_default() += 1;
                shown_by += 1;
            }
        }
        // The graph and digest more than half of the agents with a graph show; with no such majority, every agent
        // differs.
        let mode = counts.iter().find(|(_, n)| **n * 2 > shown_by).map(|((g, d), _)| (*g, Some((*d).to_owned())));
        let t_ms = self.now_ms();
        for s in &mut self.slots {
            let shown = match (&s.proc, &s.status) {
                (None, _) => Shown::Down,
                _ if s.paused => Shown::Paused,
                (Some(_), Some((_, status))) if status.ready => {
                    if mode.as_ref().is_some_and(|(graph, digest)| *graph == status.graph && *digest == status.digest) {
                        Shown::Agrees
                    } else {
                        Shown::Differs
                    }
                }
                _ => Shown::Joining,
            };
            match s.segments.last_mut() {
                Some(last) if last.shown == shown => last.to_ms = t_ms,
                Some(last) => {
                    last.to_ms = t_ms;
                    s.segments.push(Segment { from_ms: t_ms, to_ms: t_ms, shown });
                }
                None => s.segments.push(Segment { from_ms: t_ms, to_ms: t_ms, shown }),
            }
        }
    }

    /// Asks every running agent for its final state, stops the agents and returns what was recorded.
    fn finish(mut self, episodes: Vec<EpisodeResult>) -> Result<Recorded> {
        let running: Vec<usize> = self.running().collect();
        for &slot in &running {
            if let Some(proc) = self.slots[slot].proc.as_mut() {
                proc.send(&Command::Final);
            }
        }
        let all = running.clone();
        self.wait_until(|c| all.iter().all(|s| c.slots[*s].final_state.is_some()), Duration::from_secs(30))?;
        for &slot in &running {
            let life = self.slots[slot].lives.saturating_sub(1);
            match self.slots[slot].final_state.clone() {
                Some(state) => self.log(&Event::Final { slot, life, state })?,
                None => self.problems.push(format!("agent {slot} gave no final state")),
            }
        }
        self.history.flush()?;
        let duration_ms = self.now_ms();
        let finals = running.iter().filter_map(|s| Some((*s, self.slots[*s].final_state.clone()?))).collect();
        let timeline = self.slots.iter().map(|s| s.segments.clone()).collect();
        let status = |slot: &Slot| slot.status.as_ref().map(|(_, s)| s.clone()).unwrap_or_default();
        let shm_samples_received = running.iter().map(|s| status(&self.slots[*s]).shm_samples_received).sum();
        for slot in &mut self.slots {
            if let Some(proc) = slot.proc.take() {
                proc.stop();
            }
        }
        Ok(Recorded {
            writes: std::mem::take(&mut self.writes),
            lives: std::mem::take(&mut self.lives),
            killed_replicas: std::mem::take(&mut self.killed_replicas),
            finals,
            episodes,
            timeline,
            skipped: self.skipped,
            problems: std::mem::take(&mut self.problems),
            duration_ms,
            shm_samples_received,
        })
    }
}

impl Drop for Campaign {
    fn drop(&mut self) {
        for slot in &mut self.slots {
            if let Some(proc) = slot.proc.take() {
                proc.kill();
            }
        }
    }
}

/// The input filters a network fault puts on each slot.
pub fn filters_of(fault: &Fault, slots: usize) -> BTreeMap<usize, Filter> {
    let mut filters: BTreeMap<usize, Filter> = BTreeMap::new();
    let mut drop = |to: usize, from: std::collections::BTreeSet<usize>, percent: u8| {
        filters.entry(to).or_default().drop_from.push((from, percent));
    };
    match fault {
        Fault::Loss { agents, percent } => {
            for &to in agents {
                drop(to, (0..slots).filter(|a| *a != to).collect(), *percent);
            }
        }
        Fault::OneWay { from, to, percent } => {
            for &receiver in to {
                drop(receiver, from.clone(), *percent);
            }
        }
        Fault::Partition { side } => {
            let rest: std::collections::BTreeSet<usize> = (0..slots).filter(|a| !side.contains(a)).collect();
            for &a in side {
                drop(a, rest.clone(), 100);
            }
            for &b in &rest {
                drop(b, side.clone(), 100);
            }
        }
        Fault::Pause { .. } | Fault::Kill { .. } | Fault::LateJoin { .. } | Fault::StopAtStart { .. } => {}
    }
    filters
}
