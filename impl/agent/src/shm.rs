//! An agent on shared memory alone (`transport::shm::ShmTransport`) with the real clock: every agent of the graph on
//! one host, no RTPS and so no discovery (`cortex agent --transport shm`). The default, RTPS with shared memory to
//! same-host peers, is [`crate::rtps::start_hybrid`].

use std::sync::Arc;

use transport::TransportError;
use transport::fault::FaultConfig;
use transport::shm::{ShmSettings, ShmTransport};

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
    let endpoint = transport::shm::unique_endpoint();
    let shm = ShmTransport::open(prefix, endpoint, settings).map_err(|e| AgentError::Transport {
        agent: id,
        source: TransportError::Setup { what: format!("shared memory {prefix}"), detail: e.to_string() },
    })?;
    crate::rtps::start_on(config, shm, faults)
}
