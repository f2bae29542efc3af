//! The Out direction's thread: wakes on the agent's change signals (and at least every [`MAX_WAIT`]), and
//! publishes what [`crate::graph_out`] reads from the graph: every non-static RT edge on `/tf` at the configured
//! rate, the static ones on `/tf_static` whenever they change (its writer is transient local, so a late subscriber
//! gets the last message), and each image or laser node when its attribute has a new write and its rate allows.

use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use agent::{Agent, ChangeSignal};
use bytes::Bytes;
use crossbeam_channel::Receiver;
use dsr::Dot;
use replay::ros2::TransformStamped;

use crate::config::{AttrOut, LaserOut, TfOut};
use crate::graph_out::{self, OutError};
use crate::raw::{RawCdr, RawWriter};
use crate::reader::wall_ns;
use crate::status::{Latencies, OutCounters};
use crate::{encode, lock};

/// Longest sleep between two looks at the graph.
const MAX_WAIT: Duration = Duration::from_millis(20);

/// What one output publishes.
pub(crate) enum OutKind {
    /// Non-static RT edges (`/tf`).
    Tf(TfOut),
    /// Static RT edges (`/tf_static`): the transforms last sent, without stamps, to see a change.
    TfStatic { static_frames: Vec<String>, last: Option<Vec<TransformStamped>> },
    /// An image node.
    Image(AttrOut),
    /// A laser node.
    Laser(LaserOut),
}

/// One output: its writer, what it publishes, when it last did.
pub(crate) struct Output {
    pub(crate) kind: OutKind,
    pub(crate) writer: RawWriter,
    pub(crate) min_interval: Duration,
    pub(crate) last_sent: Option<Instant>,
    pub(crate) last_dot: Option<Dot>,
}

/// What the Out thread shares with the status.
#[derive(Default)]
pub(crate) struct OutShared {
    pub(crate) counters: Mutex<Vec<OutCounters>>,
    pub(crate) bad_rt_edges: Mutex<u64>,
    pub(crate) latency: Mutex<Latencies>,
}

/// Runs until `stop` is set; `signals` are the agent's change signals.
pub(crate) fn write_loop<T: transport::Transport + 'static>(
    agent: &Agent<T>,
    mut outputs: Vec<Output>,
    signals: &Receiver<ChangeSignal>,
    shared: &OutShared,
    stop: &AtomicBool,
) {
    while !stop.load(Ordering::Relaxed) {
        let woken_at = match signals.recv_timeout(MAX_WAIT) {
            Ok(_) => Some(Instant::now()),
            Err(crossbeam_channel::RecvTimeoutError::Timeout) => None,
            Err(crossbeam_channel::RecvTimeoutError::Disconnected) => {
                std::thread::sleep(MAX_WAIT);
                None
            }
        };
        while signals.try_recv().is_ok() {}
        for (index, output) in outputs.iter_mut().enumerate() {
            let now = Instant::now();
            if output.last_sent.is_some_and(|last| now.duration_since(last) < output.min_interval) {
                continue;
            }
            match build(agent, output, shared) {
                Ok(Some((payload, dot))) => {
                    output.last_sent = Some(now);
                    output.last_dot = dot.or(output.last_dot);
                    let written = output.writer.write(RawCdr(payload), None);
                    let mut counters = lock(&shared.counters);
                    match written {
                        Ok(()) => {
                            counters[index].published += 1;
                            if let (Some(woken_at), Some(_)) = (woken_at, dot) {
                                lock(&shared.latency).record(woken_at.elapsed().as_micros() as u64);
                            }
                        }
                        Err(error) => failed(&mut counters[index], format!("DDS write failed: {error:?}")),
                    }
                }
                Ok(None) => {}
                Err(error) => {
                    output.last_sent = Some(now);
                    failed(&mut lock(&shared.counters)[index], error.to_string());
                }
            }
        }
    }
}

fn failed(counters: &mut OutCounters, reason: String) {
    counters.errors += 1;
    if counters.last_error.as_ref() != Some(&reason) {
        tracing::warn!("ros2 bridge: cannot publish {}: {reason}", counters.topic);
    }
    counters.last_error = Some(reason);
}

/// The payload `output` should send now, with the dot of the write it shows (sensors), or `None`.
fn build<T: transport::Transport + 'static>(
    agent: &Agent<T>,
    output: &mut Output,
    shared: &OutShared,
) -> Result<Option<(Bytes, Option<Dot>)>, OutError> {
    let now_ns = wall_ns();
    let last_dot = output.last_dot;
    let fresh = |dot: &Dot| Some(*dot) != last_dot;
    let read = match &mut output.kind {
        OutKind::Tf(tf) => {
            let Some((dynamic, _, bad)) =
                agent.read(|replica| graph_out::rt_transforms(replica, &tf.static_frames, now_ns))
            else {
                return Ok(None);
            };
            *lock(&shared.bad_rt_edges) = bad;
            (!dynamic.is_empty()).then(|| (encode::tf_message(&dynamic), None))
        }
        OutKind::TfStatic { static_frames, last } => {
            let Some((_, fixed, _)) = agent.read(|replica| graph_out::rt_transforms(replica, static_frames, now_ns))
            else {
                return Ok(None);
            };
            let unstamped: Vec<TransformStamped> = fixed.iter().map(without_stamp).collect();
            if fixed.is_empty() || last.as_ref() == Some(&unstamped) {
                None
            } else {
                *last = Some(unstamped);
                Some((encode::tf_message(&fixed), None))
            }
        }
        OutKind::Image(out) => agent
            .read(|replica| graph_out::image(replica, &out.node, now_ns))
            .unwrap_or(Ok(None))?
            .filter(|(dot, _)| fresh(dot))
            .map(|(dot, image)| (encode::image(&image), Some(dot))),
        OutKind::Laser(out) => agent
            .read(|replica| graph_out::laser_scan(replica, &out.node, (out.range_min_m, out.range_max_m), now_ns))
            .unwrap_or(Ok(None))?
            .filter(|(dot, _)| fresh(dot))
            .map(|(dot, scan)| (encode::laser_scan(&scan), Some(dot))),
    };
    Ok(read)
}

fn without_stamp(transform: &TransformStamped) -> TransformStamped {
    let mut transform = transform.clone();
    transform.header.sec = 0;
    transform.header.nanosec = 0;
    transform
}
