//! The raw iceoryx2 path: `transport::shm::limit` from this process to receiver processes, every size in turn.
//! A round waits for every receiver's answer (1 s at most) before the next is due, as the spike did; the latency
//! is the receiver's stamp less the sender's.

use std::path::Path;
use std::time::Duration;

use anyhow::{Context as _, ensure};
use transport::SystemClock;
use transport::shm::limit::{self, LimitSender, Wake};

use super::{Counting, Mark, Window, paced, spawn_receivers};
use crate::bench::{PAYLOAD_FILL, helper};
use crate::latency;
use crate::results::PayloadCell;
use crate::spec::{PayloadPath, PayloadPathsExperiment};

/// How long a round waits for every receiver's answer.
const ROUND_TIMEOUT: Duration = Duration::from_secs(1);
/// How long the receivers have to open the services and announce themselves.
const READY_TIMEOUT: Duration = Duration::from_secs(30);

/// Every size of `experiment` to `receivers` receiver processes of `program`.
pub(super) fn session(
    experiment: &PayloadPathsExperiment,
    receivers: u32,
    counting: &Counting,
    program: &Path,
    progress: &mut dyn FnMut(&str),
) -> anyhow::Result<Vec<PayloadCell>> {
    let prefix = format!("cortex/bench/payload/{}/n{receivers}", std::process::id());
    let largest = experiment.sizes.iter().copied().max().unwrap_or(limit::MIN_SAMPLE_BYTES);
    let sender = LimitSender::open(&prefix, receivers as usize, largest, Wake::Event)
        .context("opening the iceoryx2 services")?;
    let path = PayloadPath::Iceoryx2.name();
    let (helpers, pids) = spawn_receivers(program, receivers, |i| helper::payload_receiver_args(path, 0, &prefix, i))?;
    let ready = sender.wait_ready(READY_TIMEOUT)?;
    ensure!(ready == receivers as usize, "{ready} of {receivers} iceoryx2 receivers came up within 30 s");
    let mut round = 0u64;
    let mut cells = Vec::new();
    for &size in &experiment.sizes {
        // Each sample is made just before it is sent, as the other paths' writers make theirs
        // ([`crate::bench::payload_of`]): the copy into the loan reads bytes the writer has just written.
        let mut send = || {
            round += 1;
            let mut sample = vec![PAYLOAD_FILL; size];
            sender.round(round, &mut sample, &SystemClock, ROUND_TIMEOUT)
        };
        paced(experiment.warmup_for(size), experiment.rate_hz, |_| Ok(send().map(drop)?))?;
        let start = Mark::now(counting, &pids)?;
        let mut latencies = latency::histogram();
        paced(experiment.count, experiment.rate_hz, |_| {
            let got = send()?;
            for delivery in &got.deliveries {
                latencies.saturating_record(delivery.received_ns.saturating_sub(got.sent_ns).max(1));
            }
            Ok(())
        })?;
        let end = Mark::now(counting, &pids)?;
        let window = Window { size_bytes: size, samples: experiment.count, start, end, latencies };
        cells.push(window.cell(PayloadPath::Iceoryx2, receivers));
        progress(&format!("payload paths: raw iceoryx2 {size} B to {receivers}"));
    }
    sender.stop()?;
    for mut helper in helpers {
        helper.exited_within(Duration::from_secs(2));
    }
    Ok(cells)
}

/// A receiver process of the raw path: answers every sample until told to stop.
pub(super) fn receive(prefix: &str, index: u32) -> anyhow::Result<()> {
    limit::receive(prefix, u64::from(index), Wake::Event, &SystemClock).context("the iceoryx2 receiver")
}
