//! An agent on the RTPS transport with the real clock, optionally behind the seeded fault injector: how every agent
//! process of the workspace starts its agent (`cortex agent`, `cortex inspect`, a chaos campaign's agents, and the
//! bridge agent of the RTPS replay runner in `measure`).

use std::sync::Arc;

use transport::fault::{FaultConfig, FaultPlan};
use transport::rtps::{RtpsConfig, RtpsTransport};
use transport::{Clock, SystemClock, Transport};

use crate::{Agent, AgentConfig, AgentError};

/// The transport of an agent started by [`start`]: RTPS, possibly behind the seeded fault injector.
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
    let transport: AgentTransport = match faults {
        Some(faults) => {
            let plan = FaultPlan::new(u64::from(id.0), faults);
            Arc::new(plan.wrap(rtps, Arc::new(SystemClock) as Arc<dyn Clock>))
        }
        None => Arc::new(rtps),
    };
    Ok(Arc::new(Agent::start(config, transport, Arc::new(SystemClock))?))
}
