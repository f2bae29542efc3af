//! One hop of a small update between two agents over same-host shared memory, in one process, for counting what
//! each hop costs (`scripts/hop-footprint.sh` runs it under valgrind's cachegrind). The writer is an agent driven
//! by the main thread; the receiver an agent with threads of its own, as `cortex agent` runs it, whose change
//! callback tells the writer. Between hops the writer sleeps, so the receiver waits for each sample as at a
//! sensor's rate. `transport` runs the same loop over the agents' shared-memory transport alone (a thread that
//! takes each sample and tells the writer): the part of the cost that is not the agents'. Run natively, it prints
//! the hops' latency from the write to the receiver's callback (one process, so both threads share its caches:
//! not the figure of two processes, which `cortex bench payload` measures).
//!
//! ```text
//! hop_cost agents|transport HOPS [PAYLOAD_BYTES]
//! HOP_COST_FLUSH_MB=64 hop_cost ...    # the writer touches 64 MiB between hops, so a simulated cache starts cold
//! ```

use std::sync::Arc;
use std::sync::mpsc;
use std::time::{Duration, Instant};

use agent::{Agent, AgentConfig, AgentId};
use bytes::Bytes;
use dsr::{NewNode, attrs};
use transport::shm::{ShmSettings, ShmTransport};
use transport::{Channel, EndpointId, SystemClock, Transport};

/// The pause between two hops: the receiver is asleep when each sample comes.
const PAUSE: Duration = Duration::from_millis(2);
/// Hops before the counted ones, so that both sides' histories, caches and connections are set up.
const WARMUP_HOPS: u64 = 50;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let mode = args.next().unwrap_or_else(|| "agents".into());
    let hops: u64 = args.next().map_or(Ok(200), |s| s.parse())?;
    let payload_bytes: usize = args.next().map_or(Ok(16), |s| s.parse())?;
    let prefix = format!("cortex/hop/{}", std::process::id());
    // Small lanes: valgrind cannot map the default 8 MiB ones (and a 16 B update needs none of it).
    let settings = ShmSettings { max_sample_bytes: 1 << 16, max_endpoints: 4, ..ShmSettings::default() };
    let open = |id| ShmTransport::open(&prefix, EndpointId(id), &settings);
    let (writer, receiver) = (open(1)?, open(2)?);
    let payload = |seq: u64| {
        let mut bytes = vec![0u8; payload_bytes.max(8)];
        bytes[..8].copy_from_slice(&seq.to_le_bytes());
        Bytes::from(bytes)
    };
    match mode.as_str() {
        "transport" => transport_hops(writer, receiver, hops, payload),
        "agents" => agent_hops(writer, receiver, hops, payload),
        other => Err(format!("unknown mode {other:?}: agents or transport").into()),
    }
}

fn agent_hops(
    writer: ShmTransport,
    receiver: ShmTransport,
    hops: u64,
    payload: impl Fn(u64) -> Bytes,
) -> Result<(), Box<dyn std::error::Error>> {
    let config = |id, join_wait| AgentConfig { join_wait, ..AgentConfig::new(AgentId(id)) };
    let a = Agent::new(config(1, Duration::from_millis(50)), writer, Arc::new(SystemClock))?;
    while !a.is_ready() {
        a.pump_wait(Duration::from_millis(5));
    }
    let node = a.insert_node(NewNode::new("object", "ping"))?;
    let b = Agent::start(config(2, Duration::from_secs(10)), receiver, Arc::new(SystemClock))?;
    while b.node(node).is_none() {
        a.pump_wait(Duration::from_millis(1));
    }
    let (seen, heard) = mpsc::channel();
    b.on_change(move |_signal| {
        let _ = seen.send(Instant::now());
    });
    let latencies = write_loop(WARMUP_HOPS + hops, |seq| {
        a.set_attr(node, attrs::CAM_RGB, payload(seq))?;
        Ok(heard.recv_timeout(Duration::from_secs(10))?)
    })?;
    b.shutdown();
    print_latencies(latencies);
    Ok(())
}

/// The writer's loop: `hop` writes and waits for the receiver, returning when it heard; then the writer pauses.
/// Returns the latencies of the hops after the warm-up, from before the write to the receiver's hearing.
#[inline(never)]
fn write_loop(
    total: u64,
    mut hop: impl FnMut(u64) -> Result<Instant, Box<dyn std::error::Error>>,
) -> Result<Vec<Duration>, Box<dyn std::error::Error>> {
    // With HOP_COST_FLUSH_MB set, the writer touches that many MiB between hops, so a simulated cache holds nothing
    // of the last hop when the next starts (`cachegrind --cache-sim=yes`: its last-level misses per hop are then
    // the lines a hop touches, a cold start's cost).
    let flush_mib = std::env::var("HOP_COST_FLUSH_MB").ok().and_then(|mib| mib.parse::<usize>().ok()).unwrap_or(0);
    let mut junk = vec![0u8; flush_mib << 20];
    let mut latencies = Vec::new();
    for seq in 0..total {
        let sent = Instant::now();
        let heard = hop(seq)?;
        if seq >= WARMUP_HOPS {
            latencies.push(heard.saturating_duration_since(sent));
        }
        std::thread::sleep(PAUSE);
        flush(&mut junk, seq);
    }
    Ok(latencies)
}

/// Prints the latencies' median, 90th and 99th percentiles on standard error.
fn print_latencies(mut latencies: Vec<Duration>) {
    latencies.sort_unstable();
    let at = |q: f64| latencies.get(((latencies.len() as f64 * q) as usize).min(latencies.len().saturating_sub(1)));
    if let (Some(p50), Some(p90), Some(p99)) = (at(0.5), at(0.9), at(0.99)) {
        eprintln!("{} hops, write to receiver's hearing: p50 {p50:?}, p90 {p90:?}, p99 {p99:?}", latencies.len());
    }
}

/// Writes every cache line of `junk`.
#[inline(never)]
fn flush(junk: &mut [u8], seq: u64) {
    for line in junk.chunks_mut(64) {
        line[0] = seq as u8;
    }
    std::hint::black_box(junk);
}

fn transport_hops(
    writer: ShmTransport,
    receiver: ShmTransport,
    hops: u64,
    payload: impl Fn(u64) -> Bytes,
) -> Result<(), Box<dyn std::error::Error>> {
    let total = WARMUP_HOPS + hops;
    let (seen, heard) = mpsc::channel();
    let thread = std::thread::spawn(move || receive_loop(&receiver, total, &seen));
    let latencies = write_loop(total, |seq| {
        writer.publish(Channel::Updates, payload(seq))?;
        Ok(heard.recv_timeout(Duration::from_secs(10))?)
    })?;
    thread.join().map_err(|_| "the receiving thread panicked")?;
    print_latencies(latencies);
    Ok(())
}

/// The transport's receiver: takes `total` samples and tells the writer of each.
#[inline(never)]
fn receive_loop(receiver: &ShmTransport, total: u64, seen: &mpsc::Sender<Instant>) {
    for _ in 0..total {
        if receiver.recv_timeout(Duration::from_secs(10)).is_none() {
            return;
        }
        let _ = seen.send(Instant::now());
    }
}
