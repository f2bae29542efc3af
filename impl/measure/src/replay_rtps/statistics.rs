//! A role's BICA statistics, fetched by the bridge agent with a remote call (`runtime.components`) over the same
//! DDS engine that carries the graph.

use std::time::Duration;

use agent::Agent;
use agent::rtps::AgentTransport;

use crate::results::ComponentRow;
use crate::units::ms_from_ns;

/// How often [`role_statistics`] tries its call: with `loss=0.1` one attempt in five fails (the request or the
/// reply lost), so three attempts failed about one run in 140 (the likely cause of one CI run that had no
/// statistics); six fail about one in 20,000.
pub const STATISTICS_ATTEMPTS: usize = 6;

/// The statistics of agent `id`'s role, by a remote call from `bridge`. The call is a read, so it is tried up to
/// [`STATISTICS_ATTEMPTS`] times (1 s each): with injected faults, a request or reply can be lost like any other
/// sample.
///
/// # Errors
/// Every attempt failed; the message lists why each did.
pub fn role_statistics(bridge: &Agent<AgentTransport>, id: u32) -> Result<Vec<ComponentRow>, String> {
    let mut attempts = Vec::new();
    let reply: bica::service::ComponentsReply = loop {
        match bridge.call(agent::AgentId(id), bica::service::COMPONENTS, &(), Duration::from_secs(1)) {
            Ok(reply) => break reply,
            Err(error) if attempts.len() + 1 < STATISTICS_ATTEMPTS => attempts.push(error.to_string()),
            Err(error) => {
                attempts.push(error.to_string());
                return Err(format!("{} attempts: {}", attempts.len(), attempts.join("; ")));
            }
        }
    };
    Ok(reply
        .statistics
        .components
        .into_iter()
        .map(|c| ComponentRow {
            name: c.name,
            nominal_hz: c.nominal_hz,
            achieved_hz: c.achieved_hz,
            runs: c.counters.runs,
            misses: c.counters.misses,
            skipped_releases: c.counters.skipped_releases,
            lateness_p99_ms: ms_from_ns(c.lateness.p99_ns),
            wall_p99_ms: ms_from_ns(c.wall.p99_ns),
        })
        .collect())
}
