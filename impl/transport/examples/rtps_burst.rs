//! One RTPS writer, one RTPS reader (two participants in this process, loopback UDP): samples of the SICK TiM7xx
//! log's sizes (a 9,853 B scan delta and a 13,115 B point-cloud delta, written together 15 times a second) for a few
//! seconds, and the latency distribution of what arrives — the focused reproducer of issue 5's delivery stall.
//!
//! ```text
//! cargo run --release -p transport --example rtps_burst -- [seconds] [pairs_per_second] [size,size,...] [mode]
//! RUST_LOG=rustdds=debug cargo run --release -p transport --example rtps_burst   # rustdds' own log on stderr
//! ```
//!
//! `mode` is `separate` (the readers in their own participant, the default of `RtpsConfig`), `shared` (one
//! participant per transport: the configuration that stalled) or `both` (the default: one run of each, side by
//! side). Every sample carries its sequence number; the figures are per stage, on one monotonic clock: the due time,
//! the return of `publish` (the rustdds write), and the pop from the receiver's inbox. The first samples more than
//! 100 ms late are listed one per line, so a stall shows where it starts and how long it lasts.

use std::time::{Duration, Instant};

use bytes::{BufMut, Bytes, BytesMut};
use transport::rtps::{RtpsConfig, RtpsTransport};
use transport::{Channel, Transport};

/// The SICK TiM7xx log's two deltas (8-byte sequence number included), written at the same instant.
const SICK_SAMPLE_BYTES: [usize; 2] = [9_853, 13_115];

fn percentile(sorted: &[u64], p: f64) -> u64 {
    if sorted.is_empty() {
        return 0;
    }
    let rank = ((p / 100.0) * sorted.len() as f64).ceil() as usize;
    sorted[rank.clamp(1, sorted.len()) - 1]
}

fn summary(name: &str, mut ns: Vec<u64>) {
    ns.sort_unstable();
    let ms = |v: u64| v as f64 / 1e6;
    println!(
        "{name:<22} n={:<5} p50 {:>9.3} ms  p90 {:>9.3} ms  p99 {:>9.3} ms  max {:>9.3} ms",
        ns.len(),
        ms(percentile(&ns, 50.0)),
        ms(percentile(&ns, 90.0)),
        ms(percentile(&ns, 99.0)),
        ms(ns.last().copied().unwrap_or(0)),
    );
}

fn main() {
    let _ = tracing_subscriber::fmt()
        .with_env_filter(tracing_subscriber::EnvFilter::from_default_env())
        .with_writer(std::io::stderr)
        .with_thread_ids(true)
        .try_init();
    let mut args = std::env::args().skip(1);
    let seconds: f64 = args.next().map_or(10.0, |a| a.parse().expect("seconds"));
    let pairs_per_second: f64 = args.next().map_or(15.0, |a| a.parse().expect("pairs per second"));
    let sizes: Vec<usize> = args
        .next()
        .map_or(SICK_SAMPLE_BYTES.to_vec(), |a| a.split(',').map(|s| s.parse().expect("sample size")).collect());
    assert!(sizes.iter().all(|&s| s >= 8), "every sample carries an 8-byte sequence number");
    let modes: &[bool] = match args.next().as_deref().unwrap_or("both") {
        "separate" => &[true],
        "shared" => &[false],
        "both" => &[false, true],
        other => panic!("mode is separate, shared or both, not {other}"),
    };
    for &separate in modes {
        run(separate, seconds, pairs_per_second, &sizes);
    }
}

/// One run: a writer transport and a reader transport, `seconds` of `sizes` written together `pairs_per_second`.
fn run(separate_reader_participant: bool, seconds: f64, pairs_per_second: f64, sizes: &[usize]) {
    let prefix = format!("burst{}_{separate_reader_participant}", std::process::id());
    let config =
        RtpsConfig { domain_id: 73, topic_prefix: prefix, separate_reader_participant, ..RtpsConfig::default() };
    let writer = RtpsTransport::new(config.clone()).expect("writer participant");
    let reader = RtpsTransport::new(config).expect("reader participant");

    // Discovery: probe until the reader hears the writer, then drain.
    let deadline = Instant::now() + Duration::from_secs(30);
    loop {
        writer.publish(Channel::Updates, Bytes::copy_from_slice(&u64::MAX.to_le_bytes())).expect("probe");
        if reader.recv_timeout(Duration::from_millis(50)).is_some() {
            break;
        }
        assert!(Instant::now() < deadline, "no discovery within 30 s");
    }
    while reader.recv_timeout(Duration::from_millis(200)).is_some() {}

    let ticks = (seconds * pairs_per_second).round() as usize;
    let n = ticks * sizes.len();
    let period = Duration::from_secs_f64(1.0 / pairs_per_second);
    let samples: Vec<Bytes> = (0..n)
        .map(|seq| {
            let mut b = BytesMut::with_capacity(sizes[seq % sizes.len()]);
            b.put_u64_le(seq as u64);
            b.resize(sizes[seq % sizes.len()], (seq % 251) as u8);
            b.freeze()
        })
        .collect();

    let start = Instant::now();
    let since = move |t: Instant| t.duration_since(start).as_nanos() as u64;
    let receiving = std::thread::spawn(move || {
        let mut popped_at = vec![u64::MAX; n];
        let mut order = Vec::with_capacity(n);
        let give_up = Instant::now() + Duration::from_secs_f64(seconds + 30.0);
        while order.len() < n && Instant::now() < give_up {
            if let Some(sample) = reader.recv_timeout(Duration::from_millis(10)) {
                let seq = u64::from_le_bytes(sample.bytes[..8].try_into().expect("8 bytes")) as usize;
                if seq < n && popped_at[seq] == u64::MAX {
                    popped_at[seq] = since(Instant::now());
                    order.push(seq);
                }
            }
        }
        (popped_at, order, reader.stats())
    });

    let mut due_at = Vec::with_capacity(n);
    let mut returned_at = Vec::with_capacity(n);
    for (seq, sample) in samples.into_iter().enumerate() {
        let due = start + period * (seq / sizes.len()) as u32;
        if let Some(wait) = due.checked_duration_since(Instant::now()) {
            std::thread::sleep(wait);
        }
        due_at.push(since(due));
        writer.publish(Channel::Updates, sample).expect("publish");
        returned_at.push(since(Instant::now()));
    }
    let (popped_at, order, stats) = receiving.join().expect("receiver thread");

    let delivered = popped_at.iter().filter(|&&t| t != u64::MAX).count();
    let in_order = order.windows(2).all(|w| w[0] < w[1]);
    println!(
        "readers in {} participant: {} s, {} samples of {:?} B at {} per second: delivered {delivered}/{n}, \
         in order: {in_order}, inbox drops: {}",
        if separate_reader_participant { "a separate" } else { "the writers'" },
        seconds,
        n,
        sizes,
        pairs_per_second,
        stats.dropped_full
    );
    let write: Vec<u64> = due_at.iter().zip(&returned_at).map(|(d, r)| r.saturating_sub(*d)).collect();
    let latency: Vec<u64> =
        due_at.iter().zip(&popped_at).filter(|(_, p)| **p != u64::MAX).map(|(d, p)| p.saturating_sub(*d)).collect();
    summary("due -> write returned", write);
    summary("due -> popped", latency);
    let ms = |v: u64| v as f64 / 1e6;
    let mut late = 0;
    for seq in 0..n {
        let lateness = popped_at[seq].saturating_sub(due_at[seq]);
        if lateness > 100_000_000 {
            late += 1;
            if late <= 10 {
                println!(
                    "late: seq {seq:>4} ({:>6} B) due {:>9.3} ms, write returned {:>9.3} ms, popped {:>9.3} ms",
                    sizes[seq % sizes.len()],
                    ms(due_at[seq]),
                    ms(returned_at[seq]),
                    if popped_at[seq] == u64::MAX { f64::NAN } else { ms(popped_at[seq]) }
                );
            }
        }
    }
    println!("samples more than 100 ms late: {late}");
}
