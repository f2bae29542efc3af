//! Spike for issue 20: a raw iceoryx2 publish-subscribe of one large sample between processes on one host, beside
//! a `memcpy` of the same size in the same run (the machine's own limit).
//!
//! The parent process publishes a sample of `--size-bytes` on `cortex/spike/<pid>/ping` (one copy from a prepared
//! buffer into the loaned shared-memory sample, as an encoder writing into the loan would do); each of
//! `--receivers` child processes (this example started again with `child`) takes the sample in place, reads its
//! round number from the first eight bytes and its last byte, and answers with the round on
//! `cortex/spike/<pid>/pong`. The parent times the round trip until every child has answered. With `--wake event`
//! (the default) every waiting side blocks on an iceoryx2 event service notified after each send; `--wake poll`
//! spins with a yield instead. It is a spike, not the benchmark (`cortex bench payload` is to be that).
//!
//! ```text
//! cargo run --release -p transport --example shm_spike -- --size-bytes 4194304 --receivers 1 --rounds 200 --wake event
//! ```

use std::process::{Child, Command};
use std::time::{Duration, Instant};

use iceoryx2::prelude::*;

/// The round number that tells children to stop.
const STOP: u64 = u64::MAX;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    if args.get(1).map(String::as_str) == Some("child") {
        return child(&args[2], args[3].parse()?, args[4] == "event");
    }
    let mut size_bytes = 4 * 1024 * 1024usize;
    let mut receivers = 1usize;
    let mut rounds = 200usize;
    let mut event = true;
    let mut it = args.iter().skip(1);
    while let Some(flag) = it.next() {
        let value = it.next().ok_or("a flag needs a value")?;
        match flag.as_str() {
            "--size-bytes" => size_bytes = value.parse()?,
            "--receivers" => receivers = value.parse()?,
            "--rounds" => rounds = value.parse()?,
            "--wake" => event = value == "event",
            other => return Err(format!("unknown flag {other}").into()),
        }
    }
    let size_bytes = size_bytes.max(16);
    let prefix = format!("cortex/spike/{}", std::process::id());

    let node = NodeBuilder::new().create::<ipc::Service>()?;
    let ping = node
        .service_builder(&format!("{prefix}/ping").as_str().try_into()?)
        .publish_subscribe::<[u8]>()
        .max_subscribers(receivers + 1)
        .max_publishers(1)
        .subscriber_max_buffer_size(2)
        .history_size(0)
        .open_or_create()?;
    let pong = node
        .service_builder(&format!("{prefix}/pong").as_str().try_into()?)
        .publish_subscribe::<u64>()
        .max_publishers(receivers + 1)
        .max_subscribers(1)
        .subscriber_max_buffer_size(4 * receivers + 4)
        .history_size(0)
        .open_or_create()?;
    let ping_events = node
        .service_builder(&format!("{prefix}/ping-ev").as_str().try_into()?)
        .event()
        .max_listeners(receivers + 1)
        .open_or_create()?;
    let pong_events = node
        .service_builder(&format!("{prefix}/pong-ev").as_str().try_into()?)
        .event()
        .max_notifiers(receivers + 1)
        .open_or_create()?;
    let ping_notifier = ping_events.notifier_builder().create()?;
    let pong_listener = pong_events.listener_builder().create()?;
    let publisher = ping.publisher_builder().initial_max_slice_len(size_bytes).create()?;
    let answers = pong.subscriber_builder().create()?;

    let exe = std::env::current_exe()?;
    let mut children: Vec<Child> = (0..receivers)
        .map(|i| {
            Command::new(&exe)
                .arg("child")
                .arg(&prefix)
                .arg(i.to_string())
                .arg(if event { "event" } else { "poll" })
                .spawn()
        })
        .collect::<Result<_, _>>()?;

    // Each child announces itself with its index once its subscriber exists.
    let mut ready = 0;
    let deadline = Instant::now() + Duration::from_secs(20);
    while ready < receivers {
        while let Some(sample) = answers.receive()? {
            if *sample >= 1 << 32 {
                ready += 1;
            }
        }
        if Instant::now() > deadline {
            return Err("children did not come up".into());
        }
        std::thread::sleep(Duration::from_millis(1));
    }

    let mut source = vec![0u8; size_bytes];
    for (i, b) in source.iter_mut().enumerate() {
        *b = (i % 251) as u8;
    }
    let mut rtt_ns = Vec::with_capacity(rounds);
    let mut loan_write_send_ns = Vec::with_capacity(rounds);
    for round in 0..rounds as u64 {
        source[..8].copy_from_slice(&round.to_le_bytes());
        let t0 = Instant::now();
        let sample = publisher.loan_slice_uninit(size_bytes)?;
        let sample = sample.write_from_slice(&source);
        sample.send()?;
        if event {
            ping_notifier.notify()?;
        }
        loan_write_send_ns.push(t0.elapsed().as_nanos() as u64);
        let mut got = 0;
        while got < receivers {
            match answers.receive()? {
                Some(sample) if *sample == round => got += 1,
                Some(_) => {}
                None if event => {
                    pong_listener.timed_wait(|_| {}, Duration::from_millis(100))?;
                }
                None => std::thread::yield_now(),
            }
        }
        rtt_ns.push(t0.elapsed().as_nanos() as u64);
    }
    let stop = publisher.loan_slice_uninit(16)?;
    let mut stop_bytes = [0u8; 16];
    stop_bytes[..8].copy_from_slice(&STOP.to_le_bytes());
    stop.write_from_slice(&stop_bytes).send()?;
    ping_notifier.notify()?;
    for c in &mut children {
        c.wait()?;
    }

    // The machine's own limit in the same run: a memcpy of the same size into a buffer that stays allocated.
    let mut target = vec![0u8; size_bytes];
    let mut memcpy_ns = Vec::with_capacity(rounds);
    for round in 0..rounds {
        source[0] = round as u8;
        let t0 = Instant::now();
        target.copy_from_slice(&source);
        std::hint::black_box(&target);
        memcpy_ns.push(t0.elapsed().as_nanos() as u64);
    }

    let wake =
        if event { "event (receivers block on an iceoryx2 event)" } else { "poll (receivers spin with a yield)" };
    println!("size {size_bytes} B, {receivers} receiver process(es), {rounds} rounds, wake {wake}");
    print_row("memcpy", &mut memcpy_ns);
    print_row("iceoryx2 loan+write+send", &mut loan_write_send_ns);
    print_row("iceoryx2 round trip (all answered)", &mut rtt_ns);
    Ok(())
}

fn print_row(name: &str, ns: &mut [u64]) {
    ns.sort_unstable();
    let pick = |q: f64| ns[((ns.len() - 1) as f64 * q).round() as usize] as f64 / 1000.0;
    println!("{name:<36} p50 {:>9.1} us  p99 {:>9.1} us  max {:>9.1} us", pick(0.5), pick(0.99), pick(1.0));
}

fn child(prefix: &str, index: u64, event: bool) -> Result<(), Box<dyn std::error::Error>> {
    let node = NodeBuilder::new().create::<ipc::Service>()?;
    let ping =
        node.service_builder(&format!("{prefix}/ping").as_str().try_into()?).publish_subscribe::<[u8]>().open()?;
    let pong =
        node.service_builder(&format!("{prefix}/pong").as_str().try_into()?).publish_subscribe::<u64>().open()?;
    let ping_events = node.service_builder(&format!("{prefix}/ping-ev").as_str().try_into()?).event().open()?;
    let pong_events = node.service_builder(&format!("{prefix}/pong-ev").as_str().try_into()?).event().open()?;
    let wake = ping_events.listener_builder().create()?;
    let answered = pong_events.notifier_builder().create()?;
    let frames = ping.subscriber_builder().create()?;
    let answer = pong.publisher_builder().create()?;
    answer.loan_uninit()?.write_payload((1 << 32) + index).send()?;
    answered.notify()?;
    loop {
        let Some(sample) = frames.receive()? else {
            if event {
                wake.timed_wait(|_| {}, Duration::from_millis(100))?;
            } else {
                std::thread::yield_now();
            }
            continue;
        };
        let payload: &[u8] = &sample;
        let mut round = [0u8; 8];
        round.copy_from_slice(&payload[..8]);
        let round = u64::from_le_bytes(round);
        std::hint::black_box(payload[payload.len() - 1]);
        if round == STOP {
            return Ok(());
        }
        drop(sample);
        answer.loan_uninit()?.write_payload(round).send()?;
        if event {
            answered.notify()?;
        }
    }
}
