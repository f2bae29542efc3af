//! `cortex replay --out`'s recording: a [`replay::inproc`] network's sink that records every delta as published
//! and every application as a latency, while the replay runs.

use std::cell::Cell;
use std::collections::BTreeMap;
use std::io::{Seek, Write};
use std::sync::Arc;
use std::sync::mpsc::{Receiver, channel};

use anyhow::Context as _;
use dsr::Delta;
use hdrhistogram::Histogram;
use replay::inproc::{Delivery, InProcNetwork, Sink, SinkError};

use super::{ConvergenceWindow, RunRecorder, WriteLatency};
use crate::clock::MonoClock;
use crate::latency::{self, LatencyRecorder, PayloadClass};

struct InFlight {
    publish_ns: u64,
    class: PayloadClass,
    bytes: u64,
    remaining: usize,
    window_ns: u64,
}

/// What a [`RecordingSink`] measured, for the run's summary.
#[derive(Debug)]
pub struct LiveStats {
    /// Latency of every (delta, receiver) pair.
    pub latency: LatencyRecorder,
    /// Per-delta convergence windows.
    pub convergence: Histogram<u64>,
    /// Deltas published.
    pub writes: u64,
    /// Bytes of their encodings.
    pub published_bytes: u64,
    /// Deltas some receiver had not applied when the recording ended.
    pub writes_not_everywhere: u64,
    /// Last publication, ns on the run's clock.
    pub last_publish_ns: u64,
    /// Last application anywhere, ns on the run's clock.
    pub last_apply_ns: u64,
}

/// A [`Sink`] around an [`InProcNetwork`] that records the run as it happens: each delta when it is published (its
/// encoded bytes, on the delta channel), then each application at a receiver (a latency message), and a
/// convergence window when the last receiver has applied it. Times come from `clock`; the payload class of the
/// deltas is read from `class` when they are published (the caller sets it per message).
///
/// Memory: the deltas in flight (bounded by the network's window plus one message's deltas) and two histograms.
pub struct RecordingSink<'a, W: Write + Seek> {
    network: &'a mut InProcNetwork,
    recorder: RunRecorder<W>,
    clock: MonoClock,
    class: &'a Cell<PayloadClass>,
    deliveries: Receiver<(Delivery, u64)>,
    in_flight: BTreeMap<u64, InFlight>,
    stats: LiveStats,
}

impl<'a, W: Write + Seek> RecordingSink<'a, W> {
    /// Records what `network` delivers into `recorder` (which gets a delta channel for `dictionary`); installs
    /// the network's delivery hook.
    ///
    /// # Errors
    /// The output cannot be written.
    pub fn new(
        network: &'a mut InProcNetwork,
        mut recorder: RunRecorder<W>,
        dictionary: &str,
        clock: MonoClock,
        class: &'a Cell<PayloadClass>,
    ) -> anyhow::Result<Self> {
        recorder.add_delta_channel(dictionary)?;
        let (sender, deliveries) = channel();
        // Drained after every publish and flush, so it holds at most one call's deliveries.
        network.on_delivery(move |delivery| {
            let _ = sender.send((delivery, clock.now_ns()));
        });
        let stats = LiveStats {
            latency: LatencyRecorder::new(),
            convergence: latency::histogram(),
            writes: 0,
            published_bytes: 0,
            writes_not_everywhere: 0,
            last_publish_ns: 0,
            last_apply_ns: 0,
        };
        Ok(RecordingSink { network, recorder, clock, class, deliveries, in_flight: BTreeMap::new(), stats })
    }

    fn drain(&mut self) -> anyhow::Result<()> {
        let receivers = self.network.receivers().len();
        while let Ok((delivery, apply_ns)) = self.deliveries.try_recv() {
            let flight = self.in_flight.get_mut(&delivery.index).context("a delivery of an unknown delta")?;
            let latency_ns = apply_ns.saturating_sub(flight.publish_ns);
            flight.remaining -= 1;
            flight.window_ns = flight.window_ns.max(latency_ns);
            let (class, publish_ns, bytes) = (flight.class, flight.publish_ns, flight.bytes);
            self.stats.latency.record(class, latency_ns);
            self.stats.last_apply_ns = self.stats.last_apply_ns.max(apply_ns);
            self.recorder.latency(&WriteLatency {
                seq: delivery.index,
                class,
                receiver: delivery.receiver as u32 + 1,
                publish_ns,
                apply_ns,
                latency_ns,
                bytes,
            })?;
            if flight.remaining == 0 {
                let window_ns = flight.window_ns.max(1);
                self.in_flight.remove(&delivery.index);
                self.stats.convergence.saturating_record(window_ns);
                self.recorder.convergence(&ConvergenceWindow {
                    seq: delivery.index,
                    class,
                    publish_ns,
                    converged_ns: apply_ns,
                    window_ns,
                    receivers: receivers as u32,
                })?;
            }
        }
        Ok(())
    }

    /// Ends the recording's live part: returns the recorder (to add the summary and finish it) and what was measured.
    pub fn finish(self) -> (RunRecorder<W>, LiveStats) {
        let mut stats = self.stats;
        stats.writes_not_everywhere = self.in_flight.len() as u64;
        (self.recorder, stats)
    }
}

fn recording_failed(error: anyhow::Error) -> SinkError {
    SinkError::Transport(format!("cannot record the run: {error:#}"))
}

impl<W: Write + Seek> Sink for RecordingSink<'_, W> {
    fn publish(&mut self, deltas: &[Arc<Delta>]) -> Result<(), SinkError> {
        let first = self.network.stats().deltas;
        let publish_ns = self.clock.now_ns();
        let class = self.class.get();
        let receivers = self.network.receivers().len();
        for (i, delta) in deltas.iter().enumerate() {
            let index = first + i as u64;
            let bytes = delta.encode();
            self.recorder.delta(index, publish_ns, &bytes).map_err(recording_failed)?;
            self.stats.writes += 1;
            self.stats.published_bytes += bytes.len() as u64;
            self.stats.last_publish_ns = publish_ns;
            if receivers > 0 {
                let flight =
                    InFlight { publish_ns, class, bytes: bytes.len() as u64, remaining: receivers, window_ns: 0 };
                self.in_flight.insert(index, flight);
            }
        }
        let published = self.network.publish(deltas);
        self.drain().map_err(recording_failed)?;
        published
    }

    fn flush(&mut self) -> Result<(), SinkError> {
        let flushed = self.network.flush();
        self.drain().map_err(recording_failed)?;
        flushed
    }
}
