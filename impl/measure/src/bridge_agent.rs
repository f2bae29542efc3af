//! A log played into the graph by an agent: the bridge agent of the RTPS replay ([`crate::replay_rtps`]) and of
//! `cortex agent --role bridge`. The log is paced on the monotonic clock and each message is written into the
//! agent's graph through `replay::Bridge`; the agent publishes the deltas.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use agent::Agent;
use agent::rtps::AgentTransport;

/// What [`play_log`] played.
#[derive(Debug, Clone, Default)]
pub struct Played {
    /// The bridge's counters.
    pub bridge: replay::BridgeStats,
    /// Messages, bytes, deltas (each published by the agent) and loops, as the in-process replay counts them.
    pub drive: replay::inproc::DriveStats,
}

/// Paces `log` on the monotonic clock and writes each message into the agent's graph through `replay::Bridge` (the
/// agent publishes the deltas), until the log has been played `loops` times or `stop` is set. `on_deltas` sees the
/// deltas of each message once the agent has published them.
///
/// # Errors
/// The agent refuses a write (it has no graph yet, or its id collides), or `on_deltas` fails.
pub fn play_log(
    agent: &Agent<AgentTransport>,
    log: &replay::Log,
    options: replay::BridgeOptions,
    rate: replay::Rate,
    loops: u32,
    stop: &AtomicBool,
    on_deltas: &mut dyn FnMut(&[Arc<dsr::Delta>]) -> anyhow::Result<()>,
) -> anyhow::Result<Played> {
    let mut bridge = replay::Bridge::new(options);
    let mut played = Played::default();
    let origin = Instant::now();
    let clock = move || origin.elapsed().as_nanos() as u64;
    for item in replay::Pacer::new(&log.messages, rate, loops, clock) {
        loop {
            if stop.load(Ordering::SeqCst) {
                played.bridge = bridge.stats().clone();
                return Ok(played);
            }
            let now = clock();
            if now >= item.due_ns {
                break;
            }
            std::thread::sleep(Duration::from_nanos(item.due_ns - now).min(Duration::from_millis(50)));
        }
        played.drive.messages += 1;
        played.drive.bytes += item.message.data.len() as u64;
        played.drive.loops = played.drive.loops.max(item.loop_index + 1);
        let deltas = agent.update(|replica, now_ns| {
            let deltas = bridge.ingest(replica, now_ns, item.message, item.shift_ns);
            (deltas.clone(), deltas)
        })?;
        played.drive.deltas += deltas.len() as u64;
        on_deltas(&deltas)?;
    }
    played.bridge = bridge.stats().clone();
    Ok(played)
}
