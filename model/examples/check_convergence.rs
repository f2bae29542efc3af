//! Runs the convergence model once and prints the report: `cargo run --release -p model --example
//! check_convergence -- [replicas] [ops] [network] [ticks] [syncs] [history]`.

fn main() {
    let mut args = std::env::args().skip(1);
    let mut config = model::convergence::ConvergenceConfig::default();
    if let Some(n) = args.next() {
        config.replicas = n.parse().expect("replicas");
    }
    if let Some(k) = args.next() {
        config.ops = k.parse().expect("ops");
    }
    if let Some(network) = args.next() {
        config.network = network.parse().expect("network");
    }
    if let Some(ticks) = args.next() {
        config.ticks = ticks.parse().expect("ticks");
    }
    if let Some(syncs) = args.next() {
        config.syncs = syncs.parse().expect("syncs");
    }
    if let Some(history) = args.next() {
        config.history = history.parse().expect("history");
    }
    let options = model::CheckOptions { progress: true, ..Default::default() };
    let report = model::convergence::check_convergence(&config, &options);
    print!("{}", report.to_text());
}
