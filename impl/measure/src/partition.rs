//! Reconvergence after a partition heals, with real agents (`agent::Agent`, their own threads, anti-entropy) on
//! the in-process bus or on RTPS (one rustdds participant per agent, in this process, loopback UDP), behind the
//! seeded fault injector, which cuts the partition on the receiving side.
//!
//! One run: `agents` agents join (the first starts alone, the others receive its graph); the first inserts a node;
//! the last agent is cut off from all others; for `partition` both sides write an attribute of the node at
//! `rate_hz` (the first agent and the isolated one); then the partition heals, writes stop, and the run measures
//! the time from the heal until every agent has the same digest. Anti-entropy announces every `announce_period`,
//! which bounds what this time can be; the result states it.

use std::sync::Arc;
use std::time::{Duration, Instant};

use agent::{Agent, AgentConfig, AgentId};
use anyhow::Context as _;
use dsr::{NewNode, attrs};
use transport::fault::{FaultInjector, FaultPlan};
use transport::inproc::Bus;
use transport::rtps::{RtpsConfig, RtpsTransport};
use transport::{Clock, SystemClock, Transport};

use crate::clock::MonoClock;
use crate::results::PartitionResult;
use crate::spec::Link;

pub use crate::spec::PartitionConfig;

/// Runs one partition experiment.
///
/// # Errors
/// Fewer than 2 agents, a link with processes (not supported here), an agent that cannot start or join, or a write
/// an agent refuses.
pub fn run(config: &PartitionConfig) -> anyhow::Result<PartitionResult> {
    anyhow::ensure!(config.agents >= 2, "a partition needs at least 2 agents, not {}", config.agents);
    match config.link {
        Link::InProc => {
            let bus = Bus::new();
            run_on(config, || Ok(bus.attach(1 << 16)))
        }
        Link::Rtps { domain_id } => {
            let topic_prefix = format!("partition{}_{}", std::process::id(), crate::clock::run_number());
            run_on(config, || {
                let rtps = RtpsConfig { domain_id, topic_prefix: topic_prefix.clone(), ..RtpsConfig::default() };
                RtpsTransport::new(rtps).context("cannot create an RTPS participant")
            })
        }
        Link::Processes { .. } => {
            anyhow::bail!("partition runs put their agents in this process: use inproc or rtps, not rtps-processes")
        }
    }
}

fn run_on<T: Transport + 'static>(
    config: &PartitionConfig,
    mut endpoint: impl FnMut() -> anyhow::Result<T>,
) -> anyhow::Result<PartitionResult> {
    let clock = MonoClock::start();
    let plan = FaultPlan::new(config.seed, config.faults);
    let mut agents: Vec<Agent<FaultInjector<T>>> = Vec::new();
    for i in 0..config.agents {
        let transport = plan.wrap(endpoint()?, Arc::new(clock) as Arc<dyn Clock>);
        let agent_config = AgentConfig {
            join_wait: Duration::from_millis(if i == 0 { 50 } else { 3000 }),
            join_retry: Duration::from_millis(20),
            announce_period: config.announce_period,
            nonce: Some(config.seed.wrapping_mul(1000) + u64::from(i) + 1),
            ..AgentConfig::new(AgentId(i + 1))
        };
        let agent = Agent::start(agent_config, transport, Arc::new(SystemClock)).context("cannot start an agent")?;
        anyhow::ensure!(agent.wait_ready(Duration::from_secs(10)), "agent {} did not get the graph", i + 1);
        agents.push(agent);
    }
    let node = agents[0].insert_node(NewNode::new("object", "partitioned")).context("insert")?;
    let all_equal = |agents: &[Agent<FaultInjector<T>>]| {
        let first = agents[0].digest();
        first.is_some() && agents.iter().all(|a| a.digest() == first)
    };
    // Everyone has the node before the cut.
    let ready_deadline = Instant::now() + Duration::from_secs(10);
    while !(all_equal(&agents) && agents.iter().all(|a| a.node(node).is_some())) {
        anyhow::ensure!(Instant::now() < ready_deadline, "the agents did not converge before the partition");
        std::thread::sleep(Duration::from_millis(1));
    }
    let ids: Vec<_> = agents.iter().map(|a| a.transport().inner().local_id()).collect();
    let (majority, isolated) = ids.split_at(ids.len() - 1);
    plan.partition(majority, isolated);
    let period = Duration::from_secs_f64(1.0 / config.rate_hz.max(1.0));
    let started = Instant::now();
    let mut writes = 0u64;
    let last = agents.len() - 1;
    while started.elapsed() < config.partition {
        for (side, agent) in [(0usize, &agents[0]), (1, &agents[last])] {
            agent.set_attr(node, attrs::POS_X, (writes * 2 + side as u64) as f32).context("write")?;
            writes += 1;
        }
        std::thread::sleep(period);
    }
    let dropped: u64 = agents.iter().map(|a| a.status().transport.dropped_injected).sum();
    plan.heal();
    let healed = clock.now_ns();
    let deadline = healed + config.timeout.as_nanos() as u64;
    let mut reconverge_ns = None;
    while clock.now_ns() < deadline {
        if all_equal(&agents) {
            reconverge_ns = Some(clock.now_ns() - healed);
            break;
        }
        std::thread::sleep(Duration::from_micros(500));
    }
    for agent in &agents {
        agent.shutdown();
    }
    Ok(PartitionResult {
        transport: config.link.name().to_owned(),
        agents: config.agents,
        seed: config.seed,
        partition_ms: config.partition.as_millis() as u64,
        announce_period_ms: config.announce_period.as_millis() as u64,
        writes,
        dropped,
        reconverge_ns,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn agents_reconverge_after_a_healed_partition() {
        let config = PartitionConfig { partition: Duration::from_millis(150), ..PartitionConfig::default() };
        let result = run(&config).unwrap();
        assert!(result.writes > 0);
        assert!(result.dropped > 0, "the partition cut nothing: {result:?}");
        assert!(result.reconverge_ns.is_some(), "{result:?}");
    }

    #[test]
    fn agents_on_rtps_reconverge_after_a_healed_partition() {
        let config = PartitionConfig {
            partition: Duration::from_millis(150),
            link: Link::Rtps { domain_id: 79 },
            timeout: Duration::from_secs(20),
            ..PartitionConfig::default()
        };
        let result = run(&config).unwrap();
        assert_eq!(result.transport, "rtps");
        assert!(result.dropped > 0, "the partition cut nothing: {result:?}");
        assert!(result.reconverge_ns.is_some(), "{result:?}");
    }
}
