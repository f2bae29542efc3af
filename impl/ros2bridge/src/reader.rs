//! The In direction's thread: waits on the DDS readers of the input topics, takes every sample, applies the topic's
//! rate limit and writes it into the agent's graph through [`Inbound`] under one [`Agent::update`] (the deltas are
//! published after the lock). Samples `rustdds` cannot hand over (another representation) are counted as malformed.
//! A writer that goes away and comes back is matched again by `rustdds`'s discovery; the reader stays.

use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use agent::Agent;
use bytes::Bytes;
use rustdds::mio1::{Events, Interest, Poll, Token};

use crate::inbound::Inbound;
use crate::lock;
use crate::raw::{RawCdr, RawReader};
use crate::status::Latencies;

/// Longest wait for a sample before the stop flag is looked at again.
const POLL_TIMEOUT: Duration = Duration::from_millis(20);
/// Most samples taken from one reader in one round, so that one busy topic cannot starve the others.
const TAKE_PER_ROUND: usize = 256;
/// Samples whose header stamp is older than this are left out of the latency figures (a replayed or simulated
/// clock, not the publication time).
const MAX_LATENCY_US: u64 = 60_000_000;

/// One input topic's reader, with its index in the configuration.
pub(crate) struct InReader {
    pub(crate) index: usize,
    pub(crate) reader: RawReader,
    /// Whether its messages start with a `std_msgs/Header` (not TF): its stamp is then read for the latency figures.
    pub(crate) stamped: bool,
}

/// What the In thread shares with the status.
pub(crate) struct InShared {
    pub(crate) inbound: Mutex<Inbound>,
    /// Per topic: (stamp → taken, stamp → in graph).
    pub(crate) latencies: Mutex<Vec<(Latencies, Latencies)>>,
}

/// Wall-clock time, ns since the epoch (the publishers' header stamps are on it).
pub(crate) fn wall_ns() -> u64 {
    SystemTime::now().duration_since(UNIX_EPOCH).map_or(0, |d| d.as_nanos() as u64)
}

/// The header stamp of a CDR payload that starts with a `std_msgs/Header` (`int32` sec, `uint32` nanosec, little
/// endian after the 4-byte encapsulation header), if it is there and not negative.
pub(crate) fn header_stamp_ns(cdr: &[u8]) -> Option<u64> {
    let little = cdr.get(1) == Some(&1);
    let field = |at: usize| -> Option<[u8; 4]> { cdr.get(at..at + 4)?.try_into().ok() };
    let (sec, nanosec) = (field(4)?, field(8)?);
    let (sec, nanosec) = if little {
        (i32::from_le_bytes(sec), u32::from_le_bytes(nanosec))
    } else {
        (i32::from_be_bytes(sec), u32::from_be_bytes(nanosec))
    };
    u64::try_from(sec).ok().map(|sec| sec * 1_000_000_000 + u64::from(nanosec))
}

/// Runs until `stop` is set.
pub(crate) fn read_loop<T: transport::Transport + 'static>(
    agent: &Agent<T>,
    mut readers: Vec<InReader>,
    shared: &InShared,
    stop: &AtomicBool,
) {
    let origin = Instant::now();
    let mut poll = match Poll::new() {
        Ok(poll) => poll,
        Err(error) => {
            tracing::error!("ros2 bridge: cannot create a poller, the In direction is off: {error}");
            return;
        }
    };
    for (token, input) in readers.iter_mut().enumerate() {
        if let Err(error) = poll.registry().register(&mut input.reader, Token(token), Interest::READABLE) {
            tracing::warn!("ros2 bridge: cannot wait on input {}: {error}; it is polled", input.index);
        }
    }
    let mut events = Events::with_capacity(16);
    while !stop.load(Ordering::Relaxed) {
        if let Err(error) = poll.poll(&mut events, Some(POLL_TIMEOUT))
            && error.kind() != std::io::ErrorKind::Interrupted
        {
            tracing::error!("ros2 bridge: poll failed: {error}");
            std::thread::sleep(Duration::from_millis(5));
        }
        for input in &readers {
            input.reader.drain_read_notifications();
            for _ in 0..TAKE_PER_ROUND {
                match input.reader.try_take_one() {
                    Ok(Some(change)) => {
                        let RawCdr(bytes) = change.into_value();
                        let arrival_ns = origin.elapsed().as_nanos() as u64;
                        take_one(agent, input, shared, bytes, arrival_ns);
                    }
                    Ok(None) => break,
                    Err(error) => {
                        let reason = format!("rustdds could not hand the sample over: {error:?}");
                        lock(&shared.inbound).malformed(input.index, reason);
                    }
                }
            }
        }
    }
}

/// One sample: rate limit, graph write, latency figures.
fn take_one<T: transport::Transport + 'static>(
    agent: &Agent<T>,
    input: &InReader,
    shared: &InShared,
    bytes: Bytes,
    arrival_ns: u64,
) {
    let stamp_ns = if input.stamped { header_stamp_ns(&bytes) } else { None };
    let taken_wall_ns = wall_ns();
    if !lock(&shared.inbound).admit(input.index, arrival_ns) {
        return;
    }
    let written = agent.update(|replica, now_ns| {
        let deltas = lock(&shared.inbound).write(input.index, replica, now_ns, bytes);
        (deltas.clone(), deltas)
    });
    match written {
        Ok(deltas) if !deltas.is_empty() => {
            let Some(stamp_ns) = stamp_ns else { return };
            let in_graph_wall_ns = wall_ns();
            let age_us =
                |at_ns: u64| at_ns.checked_sub(stamp_ns).map(|ns| ns / 1000).filter(|&us| us <= MAX_LATENCY_US);
            let mut latencies = lock(&shared.latencies);
            if let (Some((taken, in_graph)), Some(taken_us), Some(graph_us)) =
                (latencies.get_mut(input.index), age_us(taken_wall_ns), age_us(in_graph_wall_ns))
            {
                taken.record(taken_us);
                in_graph.record(graph_us);
            }
        }
        Ok(_) => {}
        Err(error) => {
            lock(&shared.inbound).malformed(input.index, format!("the agent refused the write: {error}"));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::encode::{header_at, laser_scan};

    #[test]
    fn the_header_stamp_is_read_from_the_payload_and_a_short_one_has_none() {
        let scan = replay::ros2::LaserScan {
            header: header_at(1_700_000_000_000_000_123, "l"),
            angle_min: 0.0,
            angle_max: 0.0,
            angle_increment: 0.0,
            time_increment: 0.0,
            scan_time: 0.0,
            range_min: 0.0,
            range_max: 0.0,
            ranges: vec![],
            intensities: vec![],
        };
        let bytes = laser_scan(&scan);
        assert_eq!(header_stamp_ns(&bytes), Some(1_700_000_000_000_000_123));
        assert_eq!(header_stamp_ns(&bytes[..11]), None);
        let big = [0u8, 0, 0, 0, 0, 0, 0, 2, 0, 0, 0, 3];
        assert_eq!(header_stamp_ns(&big), Some(2_000_000_003));
    }
}
