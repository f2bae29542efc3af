//! The hybrid transport's send and receive rules between transports of this process (issue 20): two hybrids find
//! each other on their lanes and then move samples through shared memory alone (nothing more by RTPS); a plain RTPS
//! transport beside them (a process without lanes, like another host) makes the writer send by RTPS as well, and
//! the same-host reader still takes each sample once, dropping the RTPS copy; a sample published in pieces arrives
//! whole by both paths. Claims on counts, never on speed.

use std::sync::Arc;
use std::time::{Duration, Instant};

use bytes::Bytes;
use transport::hybrid::HybridTransport;
use transport::rtps::{RtpsConfig, RtpsTransport};
use transport::shm::ShmSettings;
use transport::{Channel, SystemClock, Transport};

const DOMAIN: u16 = 78;

fn rtps(prefix: &str) -> RtpsConfig {
    RtpsConfig { domain_id: DOMAIN, topic_prefix: prefix.into(), ..RtpsConfig::default() }
}

fn hybrid(prefix: &str) -> HybridTransport {
    let lanes = format!("cortex/test/{}/{prefix}", std::process::id());
    let settings = ShmSettings { max_sample_bytes: 1 << 20, ..ShmSettings::default() };
    HybridTransport::new(rtps(prefix), &lanes, &settings, Arc::new(SystemClock)).expect("a hybrid transport")
}

/// Waits (bounded) until `until` holds, panicking with `what` after 20 s.
fn wait(what: &str, until: impl Fn() -> bool) {
    let deadline = Instant::now() + Duration::from_secs(20);
    while !until() {
        assert!(Instant::now() < deadline, "not within 20 s: {what}");
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// The bytes of every sample `to` receives until none comes for `quiet`.
fn drain(to: &dyn Transport, quiet: Duration) -> Vec<Bytes> {
    let mut got = Vec::new();
    while let Some(sample) = to.recv_timeout(quiet) {
        got.push(sample.bytes);
    }
    got
}

#[test]
fn same_host_hybrids_send_by_the_lane_alone_and_a_reader_without_lanes_gets_rtps_with_no_sample_twice() {
    let prefix = format!("hy{}", std::process::id());
    let (a, b) = (hybrid(&prefix), hybrid(&prefix));
    assert!(a.has_lanes() && b.has_lanes());
    wait("the hybrids hear each other's hellos and their RTPS readers match", || {
        a.stats().same_host_peers == 1
            && b.stats().same_host_peers == 1
            && a.rtps().matched_readers(Channel::Updates, |_| true) > 0
    });
    drain(&b, Duration::from_millis(200));

    let rtps_before = a.rtps().stats().samples_sent;
    let samples: Vec<Bytes> = (0..10u8).map(|i| Bytes::from(vec![i; 1000])).collect();
    for sample in &samples {
        a.publish(Channel::Updates, sample.clone()).unwrap();
    }
    assert_eq!(drain(&b, Duration::from_millis(500)), samples, "each sample once, in order");
    assert_eq!(a.rtps().stats().samples_sent, rtps_before, "nothing went by RTPS between same-host peers");
    assert_eq!(a.stats().shm_samples_sent, 10);

    // A transport without lanes on the same domain and prefix: to the hybrids, another host.
    let plain = RtpsTransport::new(rtps(&prefix)).unwrap();
    wait("the writer's updates writer matches the reader without lanes", || {
        a.rtps().matched_readers(Channel::Updates, |_| true) == 2
    });
    drain(&b, Duration::from_millis(200));
    drain(&plain, Duration::from_millis(200));
    let duplicates_before = b.stats().same_host_duplicates;
    for sample in &samples {
        a.publish(Channel::Updates, sample.clone()).unwrap();
    }
    assert_eq!(drain(&plain, Duration::from_millis(500)), samples, "the other host gets every sample by RTPS");
    assert_eq!(drain(&b, Duration::from_millis(500)), samples, "the same-host reader still gets each sample once");
    assert_eq!(a.stats().shm_samples_sent, 20);
    assert_eq!(b.stats().same_host_duplicates - duplicates_before, 10, "the RTPS copies were dropped");

    // The same samples in pieces (as an agent publishes a delta with a camera frame): copied piece by piece into the
    // lane, joined into one buffer for RTPS, which the other host needs.
    for sample in &samples {
        let (head, tail) = sample.split_at(300);
        a.publish_pieces(Channel::Updates, &[head, tail]).unwrap();
    }
    assert_eq!(drain(&plain, Duration::from_millis(500)), samples, "the other host gets the pieces joined by RTPS");
    assert_eq!(drain(&b, Duration::from_millis(500)), samples, "the same-host reader gets them joined, once");
    assert_eq!(a.stats().shm_samples_sent, 30);
}
