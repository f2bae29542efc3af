//! Spike for issue 20: a raw iceoryx2 publish-subscribe of one large sample between processes on one host, beside
//! a `memcpy` of the same size in the same run (the machine's own limit).
//!
//! The measurement is `transport::shm::limit` (the same code `cortex bench payload` runs as its raw iceoryx2 and
//! memcpy paths): this process is the [`LimitSender`]; each of `--receivers` child processes (this example started
//! again with `child`) runs [`limit::receive`]. It prints the one-way latency (send to each child's take of the
//! sample, wall clock), the round trip until every child answered, and the `memcpy`. `cortex bench payload` is the
//! benchmark; this is the spike it grew from.
//!
//! ```text
//! cargo run --release -p transport --example shm_spike -- --size-bytes 4194304 --receivers 1 --rounds 200 --wake event
//! ```

use std::process::{Child, Command};
use std::time::Duration;

use transport::SystemClock;
use transport::shm::limit::{self, LimitSender, Wake};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    if args.get(1).map(String::as_str) == Some("child") {
        let (Some(prefix), Some(index), Some(wake)) = (args.get(2), args.get(3), args.get(4)) else {
            return Err("usage: shm_spike child PREFIX INDEX event|poll".into());
        };
        return Ok(limit::receive(prefix, index.parse()?, wake_of(wake)?, &SystemClock)?);
    }
    let mut size_bytes = 4 * 1024 * 1024usize;
    let mut receivers = 1usize;
    let mut rounds = 200usize;
    let mut wake = Wake::Event;
    let mut it = args.iter().skip(1);
    while let Some(flag) = it.next() {
        let value = it.next().ok_or("a flag needs a value")?;
        match flag.as_str() {
            "--size-bytes" => size_bytes = value.parse()?,
            "--receivers" => receivers = value.parse()?,
            "--rounds" => rounds = value.parse()?,
            "--wake" => wake = wake_of(value)?,
            other => return Err(format!("unknown flag {other}").into()),
        }
    }
    if rounds == 0 || receivers == 0 {
        return Err("--rounds and --receivers must be positive".into());
    }
    let size_bytes = size_bytes.max(limit::MIN_SAMPLE_BYTES);
    let prefix = format!("cortex/spike/{}", std::process::id());
    let sender = LimitSender::open(&prefix, receivers, size_bytes, wake)?;
    let exe = std::env::current_exe()?;
    let mut children: Vec<Child> = (0..receivers)
        .map(|i| Command::new(&exe).args(["child", &prefix, &i.to_string(), wake.name()]).spawn())
        .collect::<Result<_, _>>()?;
    if sender.wait_ready(Duration::from_secs(20))? < receivers {
        return Err("children did not come up".into());
    }

    let mut sample: Vec<u8> = (0..size_bytes).map(|i| (i % 251) as u8).collect();
    let (mut one_way_ns, mut round_trip_ns, mut send_ns) = (Vec::new(), Vec::new(), Vec::new());
    for round in 0..rounds as u64 {
        let got = sender.round(round, &mut sample, &SystemClock, Duration::from_secs(1))?;
        if got.deliveries.len() < receivers {
            eprintln!("round {round}: {} of {receivers} answered within 1 s", got.deliveries.len());
            continue;
        }
        one_way_ns.extend(got.deliveries.iter().map(|d| d.received_ns.saturating_sub(got.sent_ns)));
        round_trip_ns.push(got.answered_ns - got.sent_ns);
        send_ns.push(got.send_done_ns - got.sent_ns);
    }
    sender.stop()?;
    for c in &mut children {
        c.wait()?;
    }
    let mut memcpy_ns = limit::memcpy_ns(size_bytes, rounds);

    println!("size {size_bytes} B, {receivers} receiver process(es), {rounds} rounds, wake {}", wake.name());
    print_row("memcpy", &mut memcpy_ns);
    print_row("iceoryx2 loan+write+send", &mut send_ns);
    print_row("iceoryx2 one way (each receiver)", &mut one_way_ns);
    print_row("iceoryx2 round trip (all answered)", &mut round_trip_ns);
    Ok(())
}

fn wake_of(name: &str) -> Result<Wake, String> {
    match name {
        "event" => Ok(Wake::Event),
        "poll" => Ok(Wake::Poll),
        other => Err(format!("--wake {other}: event or poll")),
    }
}

fn print_row(name: &str, ns: &mut [u64]) {
    if ns.is_empty() {
        println!("{name:<36} no samples");
        return;
    }
    ns.sort_unstable();
    let pick = |q: f64| ns[((ns.len() - 1) as f64 * q).round() as usize] as f64 / 1000.0;
    println!("{name:<36} p50 {:>9.1} us  p99 {:>9.1} us  max {:>9.1} us", pick(0.5), pick(0.99), pick(1.0));
}
