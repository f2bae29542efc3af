//! Two RTPS transports on this host (loopback, default discovery) exchange samples on every channel, including
//! a paced burst of large samples and fragmented samples at a sensor's rate; nothing is lost or delivered back to its
//! writer.

use std::time::{Duration, Instant};

use bytes::Bytes;
use transport::rtps::{RtpsConfig, RtpsTransport, UpdateDelivery, estimated_wire_bytes};
use transport::{Channel, EndpointId, Transport, TransportError};

fn config(prefix: &str) -> RtpsConfig {
    RtpsConfig { domain_id: 77, topic_prefix: prefix.into(), ..RtpsConfig::default() }
}

/// Waits (bounded) until `b` sees a probe from `a`: discovery is done when samples flow.
fn wait_for_match(a: &RtpsTransport, b: &RtpsTransport) {
    let deadline = Instant::now() + Duration::from_secs(20);
    while Instant::now() < deadline {
        a.publish(Channel::Calls, Bytes::from_static(b"probe")).unwrap();
        if b.recv_timeout(Duration::from_millis(100)).is_some() {
            while b.recv_timeout(Duration::from_millis(200)).is_some() {}
            return;
        }
    }
    panic!("participants did not discover each other within 20 s");
}

#[test]
fn loopback_delivers_everything_in_order_per_channel() {
    let prefix = format!("t{}", std::process::id());
    let a = RtpsTransport::new(config(&prefix)).unwrap();
    let b = RtpsTransport::new(config(&prefix)).unwrap();
    assert_ne!(a.local_id(), b.local_id());
    // `Multicast::Auto`: multicast exactly where the loopback is multicast-capable (scripts/test.sh runs this test
    // again in a namespace where it is).
    assert_eq!(a.multicast(), transport::rtps::loopback_multicast_capable());
    wait_for_match(&a, &b);
    while a.try_recv().is_some() {}

    // 2000 small samples: more than rustdds' default 64-sample limit.
    for i in 0..2000u32 {
        a.publish(Channel::Updates, Bytes::copy_from_slice(&i.to_le_bytes())).unwrap();
    }
    // 24 x 1 MiB on the sync channel: paced, not stalled.
    let big = Bytes::from(vec![0xAB; 1 << 20]);
    for _ in 0..24 {
        a.publish(Channel::Sync, big.clone()).unwrap();
    }
    let mut updates = Vec::new();
    let mut large = 0;
    let deadline = Instant::now() + Duration::from_secs(60);
    while (updates.len() < 2000 || large < 24) && Instant::now() < deadline {
        if let Some(sample) = b.recv_timeout(Duration::from_millis(100)) {
            assert_eq!(sample.origin, a.local_id());
            match sample.channel {
                Channel::Updates => updates.push(u32::from_le_bytes(sample.bytes[..4].try_into().unwrap())),
                Channel::Sync => {
                    assert_eq!(sample.bytes, big);
                    large += 1;
                }
                Channel::Calls | Channel::Requests => {}
            }
        }
    }
    assert_eq!(updates, (0..2000).collect::<Vec<_>>());
    assert_eq!(large, 24);
    assert!(a.try_recv().is_none(), "a participant never receives its own samples");
    let stats = a.stats();
    assert!(stats.samples_sent >= 2024 && stats.wire_bytes_sent > stats.payload_bytes_sent);
}

#[test]
fn best_effort_updates_carry_small_samples_unacknowledged_and_large_ones_reliably() {
    let prefix = format!("be{}", std::process::id());
    let config = RtpsConfig { updates: UpdateDelivery::BEST_EFFORT_SMALL, ..config(&prefix) };
    let a = RtpsTransport::new(config.clone()).unwrap();
    let b = RtpsTransport::new(config).unwrap();
    // The best-effort topic matches on its own: probe it until a small update gets through.
    let deadline = Instant::now() + Duration::from_secs(20);
    loop {
        assert!(Instant::now() < deadline, "the best-effort updates topic did not match within 20 s");
        a.publish(Channel::Updates, Bytes::from_static(b"probe")).unwrap();
        if b.recv_timeout(Duration::from_millis(100)).is_some_and(|s| s.channel == Channel::Updates) {
            break;
        }
    }
    wait_for_match(&a, &b);
    let before = a.stats();
    // 100 small samples (best-effort) with a 2 KB one (reliable) after every tenth, paced like a fast sensor.
    let large = |i: u32| {
        let mut bytes = vec![0x5A; 2048];
        bytes[..4].copy_from_slice(&i.to_le_bytes());
        Bytes::from(bytes)
    };
    for i in 0..100u32 {
        a.publish(Channel::Updates, Bytes::copy_from_slice(&i.to_le_bytes())).unwrap();
        if i % 10 == 9 {
            a.publish(Channel::Updates, large(i)).unwrap();
        }
        std::thread::sleep(Duration::from_millis(1));
    }
    let (mut small, mut big) = (Vec::new(), Vec::new());
    let deadline = Instant::now() + Duration::from_secs(30);
    while (small.len() < 100 || big.len() < 10) && Instant::now() < deadline {
        if let Some(sample) = b.recv_timeout(Duration::from_millis(100))
            && sample.channel == Channel::Updates
        {
            let index = u32::from_le_bytes(sample.bytes[..4].try_into().unwrap());
            if sample.bytes.len() == 2048 {
                assert_eq!(sample.bytes, large(index));
                big.push(index);
            } else if sample.bytes.len() == 4 {
                small.push(index);
            }
        }
    }
    // On a quiet loopback nothing is lost; each topic keeps its writer's order (the two topics may interleave).
    assert_eq!(small, (0..100).collect::<Vec<_>>());
    assert_eq!(big, (0..10).map(|k| k * 10 + 9).collect::<Vec<_>>());
    let sent = a.stats().wire_bytes_sent - before.wire_bytes_sent;
    let expected = 100 * estimated_wire_bytes(4, false) + 10 * estimated_wire_bytes(2048, true);
    assert_eq!(sent, expected as u64, "small samples are counted without a heartbeat, large ones with one");
}

#[test]
fn large_updates_travel_on_their_own_topic_and_no_small_one_overtakes_the_large_one_before_it() {
    let prefix = format!("large{}", std::process::id());
    let a = RtpsTransport::new(config(&prefix)).unwrap();
    let b = RtpsTransport::new(config(&prefix)).unwrap();
    // Both topics of updates matched: a large update and the small one after it got through.
    let deadline = Instant::now() + Duration::from_secs(20);
    'matched: loop {
        assert!(Instant::now() < deadline, "the updates topics did not match within 20 s");
        a.publish(Channel::Updates, Bytes::from(vec![0xEE; 100_000])).unwrap();
        a.publish(Channel::Updates, Bytes::from_static(b"probe")).unwrap();
        while let Some(got) = b.recv_timeout(Duration::from_millis(200)) {
            if got.bytes.len() == 100_000 {
                break 'matched;
            }
        }
    }
    while b.recv_timeout(Duration::from_millis(300)).is_some() {}
    while a.try_recv().is_some() {}
    let before = a.stats();
    // Small updates with a 300 kB one (hundreds of fragments, on the topic of large updates) before every fourth. On
    // loopback the large ones usually come first, and may overtake small ones written before them; the case of a
    // marker before its large sample (the updates behind it wait) is `large::Order`'s unit tests'.
    let sample = |i: u32| {
        let size = if i.is_multiple_of(4) { 300_000 } else { 16 };
        let mut bytes = vec![(i % 251) as u8; size];
        bytes[..4].copy_from_slice(&i.to_le_bytes());
        Bytes::from(bytes)
    };
    let n = 120u32;
    for i in 0..n {
        a.publish(Channel::Updates, sample(i)).unwrap();
        if i % 8 == 7 {
            std::thread::sleep(Duration::from_millis(2));
        }
    }
    let mut received = Vec::new();
    let deadline = Instant::now() + Duration::from_secs(60);
    while received.len() < n as usize && Instant::now() < deadline {
        if let Some(got) = b.recv_timeout(Duration::from_millis(100)) {
            assert_eq!((got.channel, got.origin), (Channel::Updates, a.local_id()));
            let i = u32::from_le_bytes(got.bytes[..4].try_into().unwrap());
            assert_eq!(got.bytes, sample(i), "sample {i} arrived whole");
            received.push(i);
        }
    }
    let mut sorted = received.clone();
    sorted.sort_unstable();
    assert_eq!(sorted, (0..n).collect::<Vec<_>>(), "every update once; no marker");
    let at = |i: u32| received.iter().position(|&r| r == i).unwrap();
    for small in (0..n).filter(|i| !i.is_multiple_of(4)) {
        assert!(
            at(small) > at(small - small % 4),
            "small update {small} came before the large one before it: {received:?}"
        );
    }
    let smalls: Vec<u32> = received.iter().copied().filter(|i| !i.is_multiple_of(4)).collect();
    assert!(smalls.is_sorted(), "the updates topic keeps its order: {received:?}");
    assert!(b.recv_timeout(Duration::from_millis(200)).is_none(), "nothing more: markers are consumed");
    let sent = a.stats().wire_bytes_sent - before.wire_bytes_sent;
    let marker = estimated_wire_bytes(16, true);
    let expected = (30 * (estimated_wire_bytes(300_000, true) + marker) + 90 * estimated_wire_bytes(16, true)) as u64;
    // Discovery may still be matching the other topics: each match makes the next write first tell the peer where
    // this transport's readers are, a 20-byte control sample on the requests topic (8 bytes of tag, a 12-byte GUID
    // prefix; `transport::rtps`), counted too (CI once saw one: 132 bytes more).
    let control = estimated_wire_bytes(20, true) as u64;
    let extra = sent.checked_sub(expected).unwrap_or_else(|| panic!("{sent} bytes counted, {expected} written"));
    assert!(
        extra.is_multiple_of(control) && extra <= 4 * control,
        "a large update counts its marker's bytes too: {sent} bytes counted, {expected} for the updates"
    );
}

#[test]
fn a_sink_gets_samples_on_the_receiving_thread_until_it_is_cleared() {
    let prefix = format!("sink{}", std::process::id());
    let a = RtpsTransport::new(config(&prefix)).unwrap();
    let b = RtpsTransport::new(config(&prefix)).unwrap();
    wait_for_match(&a, &b);
    let (tx, rx) = std::sync::mpsc::channel();
    let tx = std::sync::Mutex::new(tx);
    let sink: transport::Sink = std::sync::Arc::new(move |sample: transport::Sample| {
        let on = std::thread::current().name().map(str::to_owned);
        let _ = tx.lock().unwrap().send((sample, on));
    });
    let received = b.stats().samples_received;
    assert!(b.set_sink(Some(sink)));
    a.publish(Channel::Updates, Bytes::from_static(b"to the sink")).unwrap();
    let (sample, thread) = rx.recv_timeout(Duration::from_secs(10)).expect("the sink got the sample");
    assert_eq!(&sample.bytes[..], b"to the sink");
    assert_eq!(thread.as_deref(), Some("rtps-receive"));
    assert!(b.try_recv().is_none(), "nothing was queued");
    assert_eq!(b.stats().samples_received, received + 1, "samples handed to the sink are counted");
    // Cleared: samples are queued again.
    assert!(b.set_sink(None));
    a.publish(Channel::Updates, Bytes::from_static(b"to the inbox")).unwrap();
    let queued = b.recv_timeout(Duration::from_secs(10)).expect("queued again");
    assert_eq!(&queued.bytes[..], b"to the inbox");
    assert!(rx.try_recv().is_err());
}

/// The SICK TiM7xx log's two deltas (sequence number included): each goes as several DATA_FRAG datagrams.
const SENSOR_SAMPLE_BYTES: [usize; 2] = [9_853, 13_115];

#[test]
fn fragmented_sensor_samples_arrive_complete_and_in_order() {
    let prefix = format!("frag{}", std::process::id());
    let a = RtpsTransport::new(config(&prefix)).unwrap();
    let b = RtpsTransport::new(config(&prefix)).unwrap();
    wait_for_match(&a, &b);
    while a.try_recv().is_some() {}

    // 400 samples at 100 a second: more than the 128 reassembly buffers a rustdds reader keeps, which the duplicate
    // copies of a writer with a same-participant reader used to fill (the stall of issue 5).
    let n = 400u32;
    let sample = |i: u32| {
        let mut bytes = vec![(i % 251) as u8; SENSOR_SAMPLE_BYTES[i as usize % 2]];
        bytes[..4].copy_from_slice(&i.to_le_bytes());
        Bytes::from(bytes)
    };
    let start = Instant::now();
    for i in 0..n {
        let due = start + Duration::from_millis(10) * i;
        if let Some(wait) = due.checked_duration_since(Instant::now()) {
            std::thread::sleep(wait);
        }
        a.publish(Channel::Updates, sample(i)).unwrap();
    }
    let mut received = Vec::new();
    let deadline = Instant::now() + Duration::from_secs(60);
    while received.len() < n as usize && Instant::now() < deadline {
        if let Some(got) = b.recv_timeout(Duration::from_millis(100)) {
            assert_eq!(got.origin, a.local_id());
            let i = u32::from_le_bytes(got.bytes[..4].try_into().unwrap());
            assert_eq!(got.bytes, sample(i), "sample {i} arrived whole");
            received.push(i);
        }
    }
    assert_eq!(received, (0..n).collect::<Vec<_>>(), "every sample, once, in order");
    assert!(a.try_recv().is_none(), "a transport never receives its own samples");
}

/// Waits (bounded) until `a`'s discovery has matched `n` remote endpoints on the sync channel.
fn wait_for_sync_matches(a: &RtpsTransport, n: u64) {
    let deadline = Instant::now() + Duration::from_secs(20);
    while a.sync_matches() < n {
        assert!(Instant::now() < deadline, "only {} sync matches within 20 s, {n} expected", a.sync_matches());
        std::thread::sleep(Duration::from_millis(10));
    }
}

#[test]
fn a_directed_sample_reaches_its_peer_alone_and_discovery_is_timed() {
    let prefix = format!("d{}", std::process::id());
    let a = RtpsTransport::new(config(&prefix)).unwrap();
    let b = RtpsTransport::new(config(&prefix)).unwrap();
    let c = RtpsTransport::new(config(&prefix)).unwrap();
    // b's and c's requests and sync readers and writers: eight matches, none of them a's own reader and writer.
    wait_for_sync_matches(&a, 8);
    let times = a.discovery();
    let sync = Channel::Sync.index();
    let first_peer = times.first_participant_ns.expect("a peer was discovered");
    assert!(first_peer >= times.created_ns);
    assert!(times.writer_matched_ns[sync].is_some_and(|t| t >= times.created_ns));
    assert!(times.reader_matched_ns[sync].is_some_and(|t| t >= times.created_ns));

    let next_on = |t: &RtpsTransport, channel: Channel| {
        let deadline = Instant::now() + Duration::from_secs(20);
        while Instant::now() < deadline {
            if let Some(sample) = t.recv_timeout(Duration::from_millis(100))
                && sample.channel == channel
            {
                return sample.bytes;
            }
        }
        panic!("no {} sample within 20 s", channel.name());
    };
    // b's readers live in its second participant: a learns where from the control sample b's transport sends on
    // its requests writer before its first sample after a match (here a request, as a joining agent's would be).
    // The control sample itself reaches no inbox.
    // (VOLATILE: b's writer must have matched a's and c's readers itself, or its sample is not for them.)
    wait_for_sync_matches(&b, 8);
    wait_for_sync_matches(&c, 8);
    b.publish(Channel::Requests, Bytes::from_static(b"request from b")).unwrap();
    assert_eq!(next_on(&a, Channel::Requests), Bytes::from_static(b"request from b"));
    assert_eq!(next_on(&c, Channel::Requests), Bytes::from_static(b"request from b"));

    // Per writer, samples arrive in order: c seeing "everyone" first proves it was never sent "for b".
    a.publish_to(Channel::Sync, Bytes::from_static(b"for b"), b.local_id()).unwrap();
    a.publish(Channel::Sync, Bytes::from_static(b"everyone")).unwrap();
    assert_eq!(next_on(&b, Channel::Sync), Bytes::from_static(b"for b"));
    assert_eq!(next_on(&b, Channel::Sync), Bytes::from_static(b"everyone"));
    assert_eq!(next_on(&c, Channel::Sync), Bytes::from_static(b"everyone"), "a sample directed to b went to c too");
    assert_eq!(a.stats().unaddressed_writes, 0);

    // A peer whose reader a does not know gets its sample like everyone else, and a counts it.
    a.publish_to(Channel::Sync, Bytes::from_static(b"for someone unknown"), EndpointId(u128::MAX)).unwrap();
    assert_eq!(next_on(&c, Channel::Sync), Bytes::from_static(b"for someone unknown"));
    assert_eq!(a.stats().unaddressed_writes, 1);
}

#[test]
fn a_read_only_transport_writes_requests_alone_and_reads_every_channel() {
    let prefix = format!("ro{}", std::process::id());
    let writer = RtpsTransport::new(config(&prefix)).unwrap();
    let reader = RtpsTransport::new(RtpsConfig { read_only: true, ..config(&prefix) }).unwrap();
    for channel in [Channel::Updates, Channel::Sync, Channel::Calls] {
        let refused = reader.publish(channel, Bytes::from_static(b"not mine to write")).unwrap_err();
        assert!(matches!(refused, TransportError::ReadOnly { .. }), "{channel:?}: {refused}");
        assert!(refused.to_string().contains("read-only"), "{refused}");
    }
    // The reader's requests reach the writer; the writer's samples on every channel reach the reader.
    let deadline = Instant::now() + Duration::from_secs(20);
    loop {
        assert!(Instant::now() < deadline, "the read-only transport's request never arrived");
        reader.publish(Channel::Requests, Bytes::from_static(b"ask")).unwrap();
        if writer.recv_timeout(Duration::from_millis(100)).is_some_and(|s| s.channel == Channel::Requests) {
            break;
        }
    }
    let mut heard = std::collections::BTreeSet::new();
    while heard.len() < Channel::COUNT {
        assert!(Instant::now() < deadline, "the read-only transport heard only {heard:?}");
        for channel in Channel::ALL {
            writer.publish(channel, Bytes::from_static(b"for all")).unwrap();
        }
        while let Some(sample) = reader.recv_timeout(Duration::from_millis(100)) {
            heard.insert(sample.channel);
        }
    }
}
