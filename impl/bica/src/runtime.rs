//! The thin, impure shell around the pure [`SchedulerCore`]: it owns the components, reads
//! the injected [`Clock`], runs the decided steps, serves remote requests between steps,
//! sleeps until the next release (never busy-waits) and logs misses and periodic reports
//! through `tracing`. [`Runtime::run_until`] drives it under a virtual clock;
//! [`Driver::spawn`] runs it on its own thread with the real monotonic clock.

use std::sync::mpsc::{Receiver, RecvTimeoutError, TryRecvError};
use std::thread::JoinHandle;
use std::time::Duration;

use crate::clock::{Clock, MonotonicClock};
use crate::component::{Component, Handle, ListChange, Registry, StepContext, run_one};
use crate::component_id::ComponentId;
use crate::core::{Decision, Gate, SchedulerConfig, SchedulerCore};
use crate::error::BicaError;
use crate::remote::{Control, RemoteHandle, Request, request_queue};
use crate::stats::{Statistics, StatisticsReport};
use crate::trace::{Caller, TraceEvent};

/// Tunables of the runtime shell.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub struct RuntimeConfig {
    /// The scheduler core's configuration.
    pub scheduler: SchedulerConfig,
    /// Measure thread CPU time of steps (two thread-CPU-clock reads, about 1 µs on Linux, per measured step).
    pub cpu_time_enabled: bool,
    /// Measure a component's CPU time on a run only if this long has passed since its last measured run: every run
    /// of a component at up to 1 kHz with the default of 1 ms, while a faster component pays for the measurement at
    /// most once a millisecond. Wall time is measured on every run.
    pub cpu_time_min_interval_ns: u64,
    /// Interval of the periodic statistics report through `tracing` (0 disables it).
    pub report_interval_ns: u64,
    /// Capacity of the remote request queue.
    pub request_queue_capacity: usize,
    /// Most requests served between two steps, so a flood cannot starve the components.
    pub requests_per_gap: usize,
}

impl Default for RuntimeConfig {
    fn default() -> Self {
        Self {
            scheduler: SchedulerConfig::default(),
            cpu_time_enabled: true,
            cpu_time_min_interval_ns: 1_000_000,
            report_interval_ns: 10_000_000_000,
            request_queue_capacity: 64,
            requests_per_gap: 16,
        }
    }
}

/// What one call of [`Runtime::run_once`] did.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum RunOutcome {
    /// A top-level step ran; `result` is what the component's step returned.
    Stepped {
        /// The top-level component.
        component: ComponentId,
        /// Its step result (a failure is also counted and logged).
        result: Result<(), BicaError>,
    },
    /// Nothing due before this time.
    SleepUntil(u64),
    /// No active component.
    Idle,
    /// A stop request was received.
    Stopped,
}

/// Components, scheduler core, statistics and clock, run by one thread.
pub struct Runtime<C: Clock> {
    registry: Registry,
    core: SchedulerCore,
    stats: Statistics,
    clock: C,
    config: RuntimeConfig,
    list_changes: Vec<ListChange>,
    remote: RemoteHandle,
    requests: Receiver<Request>,
    last_report_ns: u64,
    step_failures: u64,
    last_failure_warning_ns: Option<u64>,
}

impl<C: Clock> std::fmt::Debug for Runtime<C> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Runtime").field("registry", &self.registry).field("core", &self.core).finish_non_exhaustive()
    }
}

impl<C: Clock> Runtime<C> {
    /// Creates an empty runtime reading time from `clock`.
    pub fn new(config: RuntimeConfig, clock: C) -> Self {
        let (remote, requests) = request_queue(config.request_queue_capacity.max(1));
        let last_report_ns = clock.now_ns();
        Self {
            registry: Registry::default(),
            core: SchedulerCore::new(config.scheduler.clone()),
            stats: Statistics::new(config.cpu_time_enabled, config.cpu_time_min_interval_ns),
            clock,
            config,
            list_changes: Vec::new(),
            remote,
            requests,
            last_report_ns,
            step_failures: 0,
            last_failure_warning_ns: None,
        }
    }

    /// Registers the single instance of `T`, running at most once per `period_ns`.
    pub fn register<T: Component>(&mut self, component: T, period_ns: u64) -> Result<Handle<T>, BicaError> {
        if self.registry.contains::<T>() {
            return Err(BicaError::AlreadyRegistered { component: std::any::type_name::<T>().to_owned() });
        }
        if period_ns == 0 {
            return Err(BicaError::InvalidPeriod { component: std::any::type_name::<T>().to_owned() });
        }
        let id = self.core.register(period_ns)?;
        self.registry.insert(id, component)
    }

    /// Appends `T` to the active (top-level) list.
    pub fn activate<T: Component>(&mut self) -> Result<(), BicaError> {
        let id = self.registry.handle::<T>()?.id();
        self.core.activate(id, self.clock.now_ns())
    }

    /// Removes `T` from the active list; it simply stops being stepped.
    pub fn deactivate<T: Component>(&mut self) -> Result<(), BicaError> {
        let id = self.registry.handle::<T>()?.id();
        self.core.deactivate(id, self.clock.now_ns())
    }

    /// The components.
    pub fn registry(&self) -> &Registry {
        &self.registry
    }

    /// The components, mutably (between steps).
    pub fn registry_mut(&mut self) -> &mut Registry {
        &mut self.registry
    }

    /// The scheduler core (trace, counters, active list).
    pub fn core(&self) -> &SchedulerCore {
        &self.core
    }

    /// Removes and returns the held trace events.
    pub fn drain_trace(&mut self) -> Vec<TraceEvent> {
        self.core.drain_trace()
    }

    /// The injected clock.
    pub fn clock(&self) -> &C {
        &self.clock
    }

    /// A handle other threads use to reach components.
    pub fn remote(&self) -> RemoteHandle {
        self.remote.clone()
    }

    /// Top-level steps whose component returned an error.
    pub fn step_failures(&self) -> u64 {
        self.step_failures
    }

    /// Current statistics of every component.
    pub fn statistics(&self) -> StatisticsReport {
        self.stats.report(|id| self.registry.name(id).ok(), &self.core, self.clock.now_ns())
    }

    /// Returns (and logs through `tracing`) a statistics report if the report interval has passed.
    pub fn report_if_due(&mut self) -> Option<StatisticsReport> {
        let now_ns = self.clock.now_ns();
        let interval = self.config.report_interval_ns;
        if interval == 0 || now_ns.saturating_sub(self.last_report_ns) < interval {
            return None;
        }
        self.last_report_ns = now_ns;
        let report = self.statistics();
        tracing::info!("{report}");
        Some(report)
    }

    fn serve(&mut self, request: Request) -> bool {
        match request {
            Request::Stop => false,
            Request::Run(f) => {
                let mut control = Control {
                    registry: &mut self.registry,
                    core: &mut self.core,
                    stats: &self.stats,
                    now_ns: self.clock.now_ns(),
                };
                f(&mut control);
                true
            }
        }
    }

    /// Serves up to `requests_per_gap` queued requests; returns false on a stop request.
    pub fn serve_requests(&mut self) -> bool {
        for _ in 0..self.config.requests_per_gap {
            match self.requests.try_recv() {
                Ok(request) => {
                    if !self.serve(request) {
                        return false;
                    }
                }
                Err(TryRecvError::Empty | TryRecvError::Disconnected) => break,
            }
        }
        true
    }

    /// Serves requests, then asks the core what to do and, if a component is due, steps it.
    /// Never sleeps: the caller decides how to wait for [`RunOutcome::SleepUntil`].
    pub fn run_once(&mut self) -> Result<RunOutcome, BicaError> {
        if !self.serve_requests() {
            return Ok(RunOutcome::Stopped);
        }
        let now_ns = self.clock.now_ns();
        match self.core.next_decision(now_ns)? {
            Decision::Idle => Ok(RunOutcome::Idle),
            Decision::SleepUntil(wake_ns) => Ok(RunOutcome::SleepUntil(wake_ns)),
            Decision::Step(id) => {
                let result = self.step_top_level(id, now_ns)?;
                if let Err(error) = &result {
                    self.step_failures += 1;
                    let warn = self
                        .last_failure_warning_ns
                        .is_none_or(|last| now_ns.saturating_sub(last) >= self.config.scheduler.warning_interval_ns);
                    if warn {
                        self.last_failure_warning_ns = Some(now_ns);
                        tracing::warn!(failures = self.step_failures, %error, "component step failed");
                    }
                }
                Ok(RunOutcome::Stepped { component: id, result })
            }
        }
    }

    fn step_top_level(&mut self, id: ComponentId, now_ns: u64) -> Result<Result<(), BicaError>, BicaError> {
        let Gate::Run(info) = self.core.begin_step(id, now_ns, Caller::TopLevel)? else {
            panic!("invariant: a decided top-level component is due");
        };
        let mut ctx = StepContext {
            registry: &mut self.registry,
            core: &mut self.core,
            stats: &mut self.stats,
            clock: &self.clock,
            current: id,
            step_started_ns: now_ns,
            list_changes: &mut self.list_changes,
        };
        let result = run_one(&mut ctx, id, now_ns, &info);
        let now_ns = self.clock.now_ns();
        for change in self.list_changes.drain(..) {
            match change {
                ListChange::Activate(id) => self.core.activate(id, now_ns)?,
                ListChange::Deactivate(id) => self.core.deactivate(id, now_ns)?,
            }
        }
        Ok(result)
    }

    /// Runs until the clock reaches `end_ns`, sleeping through the clock (a virtual clock
    /// jumps). Returns early on a stop request. Meant for virtual-clock tests and simulations.
    pub fn run_until(&mut self, end_ns: u64) -> Result<(), BicaError> {
        while self.clock.now_ns() < end_ns {
            match self.run_once()? {
                RunOutcome::Stepped { .. } => {}
                RunOutcome::SleepUntil(wake_ns) => self.clock.sleep_until_ns(wake_ns.min(end_ns)),
                RunOutcome::Idle => self.clock.sleep_until_ns(end_ns),
                RunOutcome::Stopped => return Ok(()),
            }
            self.report_if_due();
        }
        Ok(())
    }

    /// Runs until a stop request, waiting for the next release on the request queue so a
    /// request wakes the thread early. Never busy-loops.
    pub fn run_forever(&mut self) -> Result<(), BicaError> {
        loop {
            let wake_ns = match self.run_once()? {
                RunOutcome::Stepped { .. } => {
                    self.report_if_due();
                    continue;
                }
                RunOutcome::Stopped => return Ok(()),
                RunOutcome::SleepUntil(wake_ns) => Some(wake_ns),
                RunOutcome::Idle => None,
            };
            self.report_if_due();
            let now_ns = self.clock.now_ns();
            // Wake for the report too, so reports keep coming when nothing runs.
            let report_ns = self.last_report_ns.saturating_add(self.config.report_interval_ns.max(1));
            let wake_ns = wake_ns.unwrap_or(report_ns).min(report_ns);
            let timeout = Duration::from_nanos(wake_ns.saturating_sub(now_ns));
            match self.requests.recv_timeout(timeout) {
                Ok(request) => {
                    if !self.serve(request) {
                        return Ok(());
                    }
                }
                Err(RecvTimeoutError::Timeout) => {}
                // Unreachable while `self.remote` holds a sender; kept for completeness.
                Err(RecvTimeoutError::Disconnected) => self.clock.sleep_until_ns(wake_ns),
            }
        }
    }
}

/// A runtime on its own thread with the real monotonic clock.
#[derive(Debug)]
pub struct Driver {
    remote: RemoteHandle,
    thread: JoinHandle<Result<(), BicaError>>,
}

impl Driver {
    /// Starts a scheduler thread. `build` runs on that thread to register and activate the
    /// components (so components need not be `Send`).
    pub fn spawn(
        config: RuntimeConfig,
        build: impl FnOnce(&mut Runtime<MonotonicClock>) -> Result<(), BicaError> + Send + 'static,
    ) -> Result<Self, BicaError> {
        let (sender, receiver) = std::sync::mpsc::sync_channel(1);
        let thread = std::thread::Builder::new()
            .name("bica-scheduler".to_owned())
            .spawn(move || {
                let mut runtime = Runtime::new(config, MonotonicClock::new());
                let built = build(&mut runtime);
                let ok = built.is_ok();
                let _ = sender.send(built.map(|()| runtime.remote()));
                if ok { runtime.run_forever() } else { Ok(()) }
            })
            .map_err(|_| BicaError::SchedulerStopped)?;
        let remote = receiver.recv().map_err(|_| BicaError::SchedulerStopped)??;
        Ok(Self { remote, thread })
    }

    /// Handle for reaching the components from other threads.
    pub fn remote(&self) -> RemoteHandle {
        self.remote.clone()
    }

    /// Stops the scheduler thread after its current step and waits for it.
    pub fn stop(self) -> Result<(), BicaError> {
        // A full queue still gets drained; retry until the stop request fits.
        loop {
            match self.remote.stop() {
                Ok(()) | Err(BicaError::SchedulerStopped) => break,
                Err(_) => std::thread::sleep(Duration::from_millis(1)),
            }
        }
        self.thread.join().map_err(|_| BicaError::SchedulerStopped)?
    }
}
