//! The transport path: the agents' same-host transport alone (`transport::shm::ShmTransport`, the transport of
//! `cortex agent --transport shm`), with no agent on either side. The writer publishes each sample on the updates
//! lane as an agent's publish does (one sample into shared memory, the other endpoints' listeners notified); each
//! receiver process takes it with `recv_timeout`, as an agent's receiving thread does, stamps it in hand (before it
//! reads the number), and answers on the sync lane the samples that ask. Samples are numbered as
//! [`super::numbering`] says, and both sides drain their transport on their own thread, as agents do.
//!
//! Against raw iceoryx2 this path adds what the transport does (four lanes looked at in turn, the wake-up of
//! every other endpoint, the copy out of shared memory or the lease); against the agents over `shm`, the agents add
//! their own work (the write under the state lock, the envelope and delta encoded and decoded, the join, the change
//! signal).

use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::Duration;

use anyhow::{Context as _, bail};
use bytes::Bytes;
use transport::shm::{ShmSettings, ShmTransport, unique_endpoint};
use transport::{Channel, Clock as _, SystemClock, Transport as _};

use super::numbering::{self, Heard, NumberedWriter, Stamps};
use super::{Counting, ReceiverReport, spawn_receivers};
use crate::bench::{helper, seq_of};
use crate::results::PayloadCell;
use crate::spec::{PayloadPath, PayloadPathsExperiment};

/// How long one wait for a sample lasts before a draining thread looks at its stop flag or the silence.
const WAIT: Duration = Duration::from_millis(100);

/// An answer: the receiver's index and the sample's number, little-endian.
fn answer(index: u32, number: u64) -> Bytes {
    [u64::from(index).to_le_bytes(), number.to_le_bytes()].concat().into()
}

/// The receiver index and number of an answer, if `bytes` is one.
fn answer_of(bytes: &[u8]) -> Option<(usize, u64)> {
    let index = u64::from_le_bytes(bytes.get(..8)?.try_into().ok()?);
    let number = u64::from_le_bytes(bytes.get(8..16)?.try_into().ok()?);
    Some((usize::try_from(index).ok()?, number))
}

/// The writer's transport and the highest number each receiver has answered, kept by a thread that drains it.
struct LaneWriter {
    transport: Arc<ShmTransport>,
    answers: Arc<Mutex<Vec<Option<u64>>>>,
    stop: Arc<AtomicBool>,
    drain: Option<JoinHandle<()>>,
    next: u64,
}

impl LaneWriter {
    /// Opens the writer's endpoint on the services of `prefix` for `receivers` receivers and starts its draining
    /// thread.
    fn open(prefix: &str, receivers: u32) -> anyhow::Result<LaneWriter> {
        let settings = ShmSettings::default();
        let transport = Arc::new(ShmTransport::open(prefix, unique_endpoint(), &settings)?);
        let answers = Arc::new(Mutex::new(vec![None; receivers as usize]));
        let stop = Arc::new(AtomicBool::new(false));
        let drain = {
            let (transport, answers, stop) = (Arc::clone(&transport), Arc::clone(&answers), Arc::clone(&stop));
            std::thread::spawn(move || {
                while !stop.load(Ordering::Relaxed) {
                    let Some(sample) = transport.recv_timeout(WAIT) else { continue };
                    let Some((index, number)) = answer_of(&sample.bytes).filter(|_| sample.channel == Channel::Sync)
                    else {
                        continue;
                    };
                    if let Some(slot) = answers.lock().unwrap_or_else(|p| p.into_inner()).get_mut(index) {
                        *slot = (*slot).max(Some(number));
                    }
                }
            })
        };
        Ok(LaneWriter { transport, answers, stop, drain: Some(drain), next: 0 })
    }
}

impl NumberedWriter for LaneWriter {
    fn next_number(&mut self) -> u64 {
        self.next += 1;
        self.next - 1
    }

    fn send(&mut self, value: Bytes) -> anyhow::Result<()> {
        Ok(self.transport.publish(Channel::Updates, value)?)
    }

    fn answered(&self, at_least: u64) -> bool {
        let answers = self.answers.lock().unwrap_or_else(|p| p.into_inner());
        answers.iter().all(|answer| answer.is_some_and(|n| n >= at_least))
    }
}

impl Drop for LaneWriter {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        self.transport.interrupt();
        if let Some(drain) = self.drain.take() {
            let _ = drain.join();
        }
    }
}

/// Every size of `experiment` from the transport here to `receivers` receiver processes of `program`, on services of
/// their own for each `start` of the session.
pub(super) fn session(
    experiment: &PayloadPathsExperiment,
    receivers: u32,
    start: u32,
    counting: &Counting,
    program: &Path,
    progress: &mut dyn FnMut(&str),
) -> anyhow::Result<Vec<PayloadCell>> {
    let path = PayloadPath::Transport;
    let prefix = format!("cortex/bench/payload/{}/transport/n{receivers}/s{start}", std::process::id());
    let mut writer = LaneWriter::open(&prefix, receivers).context("opening the shared-memory transport")?;
    let (helpers, pids) =
        spawn_receivers(program, receivers, |i| helper::payload_receiver_args(path.name(), 0, &prefix, i))?;
    numbering::measure(&mut writer, path, &path.label(), experiment, (helpers, &pids), counting, progress)
}

/// A receiver process of the transport path: receiver `index` on the services of `prefix`, until told to stop.
///
/// # Errors
/// The transport cannot be opened or an answer cannot be sent; the writer silent for [`numbering::WRITER_SILENT`].
pub(super) fn receive(prefix: &str, index: u32) -> anyhow::Result<ReceiverReport> {
    let transport = ShmTransport::open(prefix, unique_endpoint(), &ShmSettings::default())
        .context("opening the shared-memory transport")?;
    let mut stamps = Stamps::starting_at(SystemClock.now_ns());
    loop {
        let Some(sample) = transport.recv_timeout(WAIT) else {
            if stamps.writer_silent(SystemClock.now_ns()) {
                bail!("receiver {index}: the writer fell silent");
            }
            continue;
        };
        let at = SystemClock.now_ns();
        let Some(value) = seq_of(&sample.bytes).filter(|_| sample.channel == Channel::Updates) else { continue };
        // The sample (a lease, when large) goes back before the answer, as an agent's would after its join.
        drop(sample);
        match stamps.take(value, at) {
            Heard::Stop => break,
            Heard::Answer(number) => transport
                .publish(Channel::Sync, answer(index, number))
                .with_context(|| format!("receiver {index}: answering sample {number}"))?,
            Heard::Quiet => {}
        }
    }
    Ok(ReceiverReport { index, delivered: stamps.delivered })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_answer_reads_back_and_other_bytes_are_no_answer() {
        assert_eq!(answer_of(&answer(7, 1 << 40)), Some((7, 1 << 40)));
        assert_eq!(answer_of(&[1, 2, 3]), None);
    }

    #[test]
    fn a_writer_hears_the_answers_of_a_receiver_endpoint_on_its_services() {
        let prefix = format!("cortex/test/{}/bench-transport", std::process::id());
        let mut writer = LaneWriter::open(&prefix, 2).expect("the writer");
        let receiver = ShmTransport::open(&prefix, unique_endpoint(), &ShmSettings::default()).expect("a receiver");
        let (number, _) = writer.write(16, numbering::ANSWER).expect("a write");
        let sample = receiver.recv_timeout(Duration::from_secs(10)).expect("the sample");
        assert_eq!((sample.channel, seq_of(&sample.bytes)), (Channel::Updates, Some(number | numbering::ANSWER)));
        for index in 0..2 {
            receiver.publish(Channel::Sync, answer(index, number)).expect("an answer");
        }
        assert!(writer.wait_answers(number, Duration::from_secs(10)), "both receivers' answers are heard");
        assert!(!writer.answered(number + 1));
    }
}
