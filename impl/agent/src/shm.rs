//! An agent on shared memory alone (`transport::shm::ShmTransport`) with the real clock: every agent of the graph on
//! one host, no RTPS (issue 20, the same-host half; the hybrid with RTPS discovery is not written yet).

use std::sync::Arc;
use std::time::{SystemTime, UNIX_EPOCH};

use transport::fault::{FaultConfig, FaultPlan};
use transport::shm::{ShmSettings, ShmTransport};
use transport::{Clock, EndpointId, SystemClock, TransportError};

use crate::rtps::AgentTransport;
use crate::{Agent, AgentConfig, AgentError};

/// Starts an agent of `config` whose samples go through the shared-memory services `PREFIX/updates|sync|calls`
/// and `PREFIX/wake` of this host, with the real clock; `faults` as in [`crate::rtps::start`].
///
/// # Errors
/// [`AgentError::Transport`] if shared memory cannot be opened; otherwise what [`Agent::start`] refuses.
pub fn start(
    config: AgentConfig,
    prefix: &str,
    settings: &ShmSettings,
    faults: Option<FaultConfig>,
) -> Result<Arc<Agent<AgentTransport>>, AgentError> {
    let id = config.id;
    // An endpoint id no other life of any process shares: the process id beside the start time.
    let now_ns = SystemTime::now().duration_since(UNIX_EPOCH).map(|d| d.as_nanos()).unwrap_or(0);
    let endpoint = EndpointId((u128::from(std::process::id()) << 96) | (now_ns & ((1 << 96) - 1)));
    let shm = ShmTransport::open(prefix, endpoint, settings).map_err(|e| AgentError::Transport {
        agent: id,
        source: TransportError::Setup { what: format!("shared memory {prefix}"), detail: e.to_string() },
    })?;
    let transport: AgentTransport = match faults {
        Some(faults) => {
            let plan = FaultPlan::new(u64::from(id.0), faults);
            Arc::new(plan.wrap(shm, Arc::new(SystemClock) as Arc<dyn Clock>))
        }
        None => Arc::new(shm),
    };
    Ok(Arc::new(Agent::start(config, transport, Arc::new(SystemClock))?))
}
