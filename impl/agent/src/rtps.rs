//! An agent on the RTPS transport with the real clock, optionally behind the seeded fault injector: how every agent
//! process of the workspace starts its agent (`cortex agent`, `cortex inspect`, a chaos campaign's agents, and the
//! bridge agent of the RTPS replay runner in `measure`).

use std::sync::Arc;

use transport::fault::{FaultConfig, FaultPlan};
use transport::hybrid::{HybridTransport, same_host_prefix};
use transport::rtps::{RtpsConfig, RtpsTransport};
use transport::shm::ShmSettings;
use transport::{Clock, SystemClock, Transport};

use crate::{Agent, AgentConfig, AgentError};

/// The transport of an agent started by [`start`] or [`start_hybrid`] (or [`crate::shm::start`]): RTPS, RTPS with
/// same-host shared memory, or shared memory alone, possibly behind the seeded fault injector.
pub type AgentTransport = Arc<dyn Transport>;

/// Starts an agent of `config` on RTPS with the real clock. With `faults`, what the agent receives goes through the
/// seeded fault injector (seeded with the agent id), so loss, duplication, reordering and delay hit a real agent
/// with its anti-entropy.
///
/// # Errors
/// [`AgentError::Transport`] if the DDS domain cannot be joined; otherwise what [`Agent::start`] refuses.
pub fn start(
    config: AgentConfig,
    rtps: RtpsConfig,
    faults: Option<FaultConfig>,
) -> Result<Arc<Agent<AgentTransport>>, AgentError> {
    let id = config.id;
    let rtps = RtpsTransport::new(rtps).map_err(|source| AgentError::Transport { agent: id, source })?;
    start_on(config, rtps, faults)
}

/// Starts an agent of `config` on RTPS with same-host shared memory beside it ([`HybridTransport`]: lanes named
/// by [`transport::hybrid::same_host_prefix`] for the domain and topic prefix of `rtps`), with the real clock;
/// `faults` as in [`start`]. Where shared memory cannot be used the agent runs on RTPS alone, after a warning.
///
/// # Errors
/// As [`start`].
pub fn start_hybrid(
    config: AgentConfig,
    rtps: RtpsConfig,
    lanes: &ShmSettings,
    faults: Option<FaultConfig>,
) -> Result<Arc<Agent<AgentTransport>>, AgentError> {
    let id = config.id;
    let prefix = same_host_prefix(rtps.domain_id, &rtps.topic_prefix);
    let hybrid = HybridTransport::new(rtps, &prefix, lanes, Arc::new(SystemClock))
        .map_err(|source| AgentError::Transport { agent: id, source })?;
    start_on(config, hybrid, faults)
}

/// Starts the agent on `transport`, behind the fault injector when `faults` asks for it.
pub(crate) fn start_on<T: Transport + 'static>(
    config: AgentConfig,
    transport: T,
    faults: Option<FaultConfig>,
) -> Result<Arc<Agent<AgentTransport>>, AgentError> {
    let transport: AgentTransport = match faults {
        Some(faults) => {
            let plan = FaultPlan::new(u64::from(config.id.0), faults);
            Arc::new(plan.wrap(transport, Arc::new(SystemClock) as Arc<dyn Clock>))
        }
        None => Arc::new(transport),
    };
    Ok(Arc::new(Agent::start(config, transport, Arc::new(SystemClock))?))
}
