use model::scheduler::{SchedulerModelConfig, check_scheduler};
use model::{CheckOptions, Search};
#[test]
fn explore() {
    let mut c = SchedulerModelConfig::default();
    c.max_overruns = std::env::var("OV").map(|v| v.parse().unwrap()).unwrap_or(1);
    c.horizon_ns = std::env::var("HZ").map(|v| v.parse::<u64>().unwrap() * 1_000_000).unwrap_or(c.horizon_ns);
    c.max_list_changes = std::env::var("LC").map(|v| v.parse().unwrap()).unwrap_or(2);
    let r = check_scheduler(c, &CheckOptions { search: Search::Dfs, threads: 2, timeout: None, progress: false });
    eprintln!("{}", r.to_text());
}
