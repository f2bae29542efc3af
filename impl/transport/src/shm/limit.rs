//! The machine's own limit for same-host payloads (issue 20), which agents over shared memory are measured against:
//! a raw iceoryx2 publish-subscribe of one sample from a sender to N receiver processes, with no agent, no envelope
//! and no copy out of shared memory, and a `memcpy` of the same size.
//!
//! The sender ([`LimitSender`]) publishes a sample on `PREFIX/ping` — one copy from the caller's buffer into the
//! loaned shared-memory chunk, as an encoder writing into the loan would do — with its round number in the first
//! eight bytes. Each receiver ([`receive`], a process of its own) takes the sample in place, stamps the time on the
//! caller's [`Clock`] at once, reads the round and the last byte, and answers on `PREFIX/pong` with the round, its
//! index and that stamp. The sender's [`Round`] holds its own send stamp and every answer, so the caller has both the
//! one-way latency to each receiver (their clocks must be one: processes of one host reading the wall clock or
//! `CLOCK_MONOTONIC`) and the round trip until all answered. With [`Wake::Event`] every waiting side blocks on an
//! iceoryx2 event service (`PREFIX/ping-ev`, `PREFIX/pong-ev`) notified after each send; [`Wake::Poll`] spins with
//! a yield, which costs milliseconds with 8 receivers on 2 cores. `cortex bench payload` and
//! `examples/shm_spike.rs` both run this code.

use std::time::{Duration, Instant};

use iceoryx2::prelude::*;

use super::ShmError;
use crate::Clock;

/// The round number that tells receivers to stop.
pub const STOP: u64 = u64::MAX;
/// The round of a receiver's announcement that it has subscribed.
const READY: u64 = u64::MAX - 1;
/// The smallest sample: its round number.
pub const MIN_SAMPLE_BYTES: usize = 8;
/// A receiver that has heard nothing for this long stops (its sender is gone).
const RECEIVER_IDLE: Duration = Duration::from_secs(60);
/// How long one wait on an event service lasts before the waiting side looks again.
const WAIT_SLICE: Duration = Duration::from_millis(100);

/// An answer on `PREFIX/pong`: the round, the receiver's index, and when it took the sample (ns, caller's clock).
type Answer = [u64; 3];

/// How waiting sides learn that something was sent.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Wake {
    /// Block on an iceoryx2 event service notified after each send.
    Event,
    /// Spin with a yield.
    Poll,
}

impl Wake {
    /// `event` or `poll`, as command lines name it.
    pub fn name(self) -> &'static str {
        match self {
            Wake::Event => "event",
            Wake::Poll => "poll",
        }
    }
}

/// One receiver's answer to a round.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Delivery {
    /// The receiver's index.
    pub receiver: u64,
    /// When it took the sample, ns on the clock given to [`receive`].
    pub received_ns: u64,
}

/// What one round observed.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Round {
    /// When the sender began the loan, ns on the clock given to [`LimitSender::round`].
    pub sent_ns: u64,
    /// When the send (and notification) returned.
    pub send_done_ns: u64,
    /// Every answer that came back before the timeout, in arrival order.
    pub deliveries: Vec<Delivery>,
    /// When the last answer came (or the timeout passed).
    pub answered_ns: u64,
}

type Ipc = ipc::Service;

fn service_name(service: &str) -> Result<ServiceName, ShmError> {
    service.try_into().map_err(|e| ShmError::Name { name: service.to_owned(), reason: format!("{e:?}") })
}

fn open_error(what: &'static str, service: &str, error: impl std::fmt::Debug) -> ShmError {
    ShmError::Open { what, service: service.to_owned(), reason: format!("{error:?}") }
}

fn io_error(op: &'static str, service: &str, error: impl std::fmt::Debug) -> ShmError {
    ShmError::Io { op, service: service.to_owned(), reason: format!("{error:?}") }
}

/// The sending side of the raw limit: the publisher of `PREFIX/ping`, the subscriber of the answers.
pub struct LimitSender {
    prefix: String,
    receivers: usize,
    max_sample_bytes: usize,
    wake: Wake,
    publisher: iceoryx2::port::publisher::Publisher<Ipc, [u8], ()>,
    answers: iceoryx2::port::subscriber::Subscriber<Ipc, Answer, ()>,
    ping_notifier: iceoryx2::port::notifier::Notifier<Ipc>,
    pong_listener: iceoryx2::port::listener::Listener<Ipc>,
    _node: Node<Ipc>,
}

impl std::fmt::Debug for LimitSender {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LimitSender").field("prefix", &self.prefix).field("receivers", &self.receivers).finish()
    }
}

impl LimitSender {
    /// Creates the services under `prefix` for `receivers` receivers and samples up to `max_sample_bytes`.
    ///
    /// # Errors
    /// [`ShmError::Name`] for a prefix iceoryx2 refuses, [`ShmError::Open`] when shared memory is unusable or a
    /// service of another shape has the name.
    pub fn open(prefix: &str, receivers: usize, max_sample_bytes: usize, wake: Wake) -> Result<Self, ShmError> {
        iceoryx2::prelude::set_log_level(LogLevel::Error);
        let node = NodeBuilder::new().create::<Ipc>().map_err(|e| open_error("node", prefix, e))?;
        // Receivers killed in an earlier run leave dead nodes holding ports; reclaim them first.
        node.try_cleanup_dead_nodes();
        let ping_name = format!("{prefix}/ping");
        let ping = node
            .service_builder(&service_name(&ping_name)?)
            .publish_subscribe::<[u8]>()
            .max_subscribers(receivers + 1)
            .max_publishers(1)
            .subscriber_max_buffer_size(2)
            .history_size(0)
            .open_or_create()
            .map_err(|e| open_error("service", &ping_name, e))?;
        let pong_name = format!("{prefix}/pong");
        let pong = node
            .service_builder(&service_name(&pong_name)?)
            .publish_subscribe::<Answer>()
            .max_publishers(receivers + 1)
            .max_subscribers(1)
            .subscriber_max_buffer_size(4 * receivers + 4)
            .history_size(0)
            .open_or_create()
            .map_err(|e| open_error("service", &pong_name, e))?;
        let (ping_events, pong_events) = (format!("{prefix}/ping-ev"), format!("{prefix}/pong-ev"));
        let ping_ev = node
            .service_builder(&service_name(&ping_events)?)
            .event()
            .max_listeners(receivers + 1)
            .open_or_create()
            .map_err(|e| open_error("event service", &ping_events, e))?;
        let pong_ev = node
            .service_builder(&service_name(&pong_events)?)
            .event()
            .max_notifiers(receivers + 1)
            .open_or_create()
            .map_err(|e| open_error("event service", &pong_events, e))?;
        Ok(Self {
            prefix: prefix.to_owned(),
            receivers,
            max_sample_bytes,
            wake,
            publisher: ping
                .publisher_builder()
                .initial_max_slice_len(max_sample_bytes.max(MIN_SAMPLE_BYTES))
                .create()
                .map_err(|e| open_error("publisher", &ping_name, e))?,
            answers: pong.subscriber_builder().create().map_err(|e| open_error("subscriber", &pong_name, e))?,
            ping_notifier: ping_ev.notifier_builder().create().map_err(|e| open_error("notifier", &ping_events, e))?,
            pong_listener: pong_ev.listener_builder().create().map_err(|e| open_error("listener", &pong_events, e))?,
            _node: node,
        })
    }

    /// Waits until every receiver has announced itself, or `timeout`; returns how many did.
    ///
    /// # Errors
    /// [`ShmError::Io`] when receiving or waiting fails.
    pub fn wait_ready(&self, timeout: Duration) -> Result<usize, ShmError> {
        let deadline = Instant::now() + timeout;
        let mut ready = std::collections::BTreeSet::new();
        while ready.len() < self.receivers && Instant::now() < deadline {
            if let Some([READY, index, _]) = self.next_answer(deadline)? {
                ready.insert(index);
            }
        }
        Ok(ready.len())
    }

    /// Sends round `round`: writes it into the first eight bytes of `sample`, copies `sample` into a loaned chunk
    /// and sends it, then waits until every receiver answered or `timeout` passed.
    ///
    /// # Errors
    /// [`ShmError::Io`] for a sample shorter than [`MIN_SAMPLE_BYTES`] or longer than the sender's maximum, or a
    /// loan, send, notification or receive that fails.
    pub fn round(
        &self,
        round: u64,
        sample: &mut [u8],
        clock: &dyn Clock,
        timeout: Duration,
    ) -> Result<Round, ShmError> {
        let service = format!("{}/ping", self.prefix);
        if sample.len() < MIN_SAMPLE_BYTES || sample.len() > self.max_sample_bytes {
            let reason =
                format!("a sample of {} B (from {MIN_SAMPLE_BYTES} to {} B)", sample.len(), self.max_sample_bytes);
            return Err(ShmError::Io { op: "loan", service, reason });
        }
        sample[..8].copy_from_slice(&round.to_le_bytes());
        let started = Instant::now();
        let sent_ns = clock.now_ns();
        self.send(sample)?;
        let send_done_ns = clock.now_ns();
        let deadline = started + timeout;
        let mut deliveries = Vec::with_capacity(self.receivers);
        while deliveries.len() < self.receivers && Instant::now() < deadline {
            if let Some([answered, receiver, received_ns]) = self.next_answer(deadline)?
                && answered == round
            {
                deliveries.push(Delivery { receiver, received_ns });
            }
        }
        Ok(Round { sent_ns, send_done_ns, deliveries, answered_ns: clock.now_ns() })
    }

    /// Tells every receiver to stop.
    ///
    /// # Errors
    /// [`ShmError::Io`] when the loan, send or notification fails.
    pub fn stop(&self) -> Result<(), ShmError> {
        let mut stop = [0u8; MIN_SAMPLE_BYTES];
        stop.copy_from_slice(&STOP.to_le_bytes());
        self.send(&stop)
    }

    fn send(&self, bytes: &[u8]) -> Result<(), ShmError> {
        let service = format!("{}/ping", self.prefix);
        let loan = self.publisher.loan_slice_uninit(bytes.len()).map_err(|e| io_error("loan", &service, e))?;
        loan.write_from_slice(bytes).send().map_err(|e| io_error("send", &service, e))?;
        if self.wake == Wake::Event {
            self.ping_notifier.notify().map_err(|e| io_error("notify", &service, e))?;
        }
        Ok(())
    }

    /// The next answer, waiting (by the wake setting) until `deadline` at most.
    fn next_answer(&self, deadline: Instant) -> Result<Option<Answer>, ShmError> {
        let service = format!("{}/pong", self.prefix);
        loop {
            if let Some(sample) = self.answers.receive().map_err(|e| io_error("receive", &service, e))? {
                return Ok(Some(*sample));
            }
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return Ok(None);
            }
            match self.wake {
                Wake::Event => {
                    self.pong_listener
                        .timed_wait(|_| {}, left.min(WAIT_SLICE))
                        .map_err(|e| io_error("wait", &service, e))?;
                }
                Wake::Poll => std::thread::yield_now(),
            }
        }
    }
}

/// A receiver of the raw limit (run it in a process of its own): opens the services of `prefix` made by a
/// [`LimitSender`], announces itself as receiver `index`, then answers every round with the time it took the sample
/// on `clock`, until told to stop or `RECEIVER_IDLE` passes without a sample.
///
/// # Errors
/// [`ShmError::Open`] when the sender's services do not exist (open the sender first), [`ShmError::Io`] when a
/// receive, send or wait fails.
pub fn receive(prefix: &str, index: u64, wake: Wake, clock: &dyn Clock) -> Result<(), ShmError> {
    iceoryx2::prelude::set_log_level(LogLevel::Error);
    let node = NodeBuilder::new().create::<Ipc>().map_err(|e| open_error("node", prefix, e))?;
    let names = ["ping", "pong", "ping-ev", "pong-ev"].map(|name| format!("{prefix}/{name}"));
    let [ping_name, pong_name, ping_events, pong_events] = &names;
    let service = |name: &str| -> Result<ServiceName, ShmError> { service_name(name) };
    let event = |name: &str| {
        node.service_builder(&service(name)?).event().open().map_err(|e| open_error("event service", name, e))
    };
    let ping = node
        .service_builder(&service(ping_name)?)
        .publish_subscribe::<[u8]>()
        .open()
        .map_err(|e| open_error("service", ping_name, e))?;
    let pong = node
        .service_builder(&service(pong_name)?)
        .publish_subscribe::<Answer>()
        .open()
        .map_err(|e| open_error("service", pong_name, e))?;
    let wake_up =
        event(ping_events)?.listener_builder().create().map_err(|e| open_error("listener", ping_events, e))?;
    let answered =
        event(pong_events)?.notifier_builder().create().map_err(|e| open_error("notifier", pong_events, e))?;
    let frames = ping.subscriber_builder().create().map_err(|e| open_error("subscriber", ping_name, e))?;
    let answer = pong.publisher_builder().create().map_err(|e| open_error("publisher", pong_name, e))?;
    let reply = |message: Answer| -> Result<(), ShmError> {
        let loan = answer.loan_uninit().map_err(|e| io_error("loan", pong_name, e))?;
        loan.write_payload(message).send().map_err(|e| io_error("send", pong_name, e))?;
        if wake == Wake::Event {
            answered.notify().map_err(|e| io_error("notify", pong_events, e))?;
        }
        Ok(())
    };
    reply([READY, index, 0])?;
    let mut last_heard = Instant::now();
    loop {
        let Some(sample) = frames.receive().map_err(|e| io_error("receive", ping_name, e))? else {
            if last_heard.elapsed() > RECEIVER_IDLE {
                return Ok(());
            }
            match wake {
                Wake::Event => {
                    wake_up.timed_wait(|_| {}, WAIT_SLICE).map_err(|e| io_error("wait", ping_events, e))?;
                }
                Wake::Poll => std::thread::yield_now(),
            }
            continue;
        };
        let received_ns = clock.now_ns();
        last_heard = Instant::now();
        let payload: &[u8] = &sample;
        let Some(round) = payload.get(..8).and_then(|b| b.try_into().ok()).map(u64::from_le_bytes) else {
            continue;
        };
        std::hint::black_box(payload[payload.len() - 1]);
        drop(sample);
        if round == STOP {
            return Ok(());
        }
        reply([round, index, received_ns])?;
    }
}

/// `rounds` copies of a `size_bytes` buffer into one that stays allocated, each timed in ns: the machine's own
/// limit for moving a sample of that size once.
pub fn memcpy_ns(size_bytes: usize, rounds: usize) -> Vec<u64> {
    let mut source: Vec<u8> = (0..size_bytes).map(|i| (i % 251) as u8).collect();
    let mut target = vec![0u8; size_bytes];
    let mut times = Vec::with_capacity(rounds);
    for round in 0..rounds {
        if let Some(first) = source.first_mut() {
            *first = round as u8;
        }
        let started = Instant::now();
        target.copy_from_slice(&source);
        std::hint::black_box(&target);
        times.push(u64::try_from(started.elapsed().as_nanos()).unwrap_or(u64::MAX));
    }
    times
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::SystemClock;

    #[test]
    fn a_receiver_thread_answers_every_round_with_a_stamp_not_before_the_send() {
        let prefix = format!("cortex/test/{}/limit", std::process::id());
        let sender = LimitSender::open(&prefix, 1, 4096, Wake::Event).expect("sender");
        let receiver_prefix = prefix.clone();
        let receiver = std::thread::spawn(move || receive(&receiver_prefix, 7, Wake::Event, &SystemClock));
        assert_eq!(sender.wait_ready(Duration::from_secs(10)).expect("ready"), 1);
        let mut sample = vec![1u8; 4096];
        for round in 0..5 {
            let got = sender.round(round, &mut sample, &SystemClock, Duration::from_secs(5)).expect("round");
            assert_eq!(got.deliveries.len(), 1, "round {round}: {got:?}");
            assert_eq!(got.deliveries[0].receiver, 7);
            assert!(got.deliveries[0].received_ns >= got.sent_ns, "{got:?}");
        }
        sender.stop().expect("stop");
        receiver.join().expect("receiver thread").expect("receiver");
    }

    #[test]
    fn samples_outside_the_sender_sizes_are_errors_not_panics() {
        let prefix = format!("cortex/test/{}/limit-sizes", std::process::id());
        let sender = LimitSender::open(&prefix, 1, 64, Wake::Poll).expect("sender");
        for size in [0, 7, 65] {
            let error = sender.round(0, &mut vec![0u8; size], &SystemClock, Duration::ZERO).unwrap_err();
            assert!(matches!(error, ShmError::Io { op: "loan", .. }), "{error}");
        }
    }

    #[test]
    fn memcpy_times_every_round() {
        assert_eq!(memcpy_ns(1024, 3).len(), 3);
        assert_eq!(memcpy_ns(0, 2).len(), 2);
    }
}
