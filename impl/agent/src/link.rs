//! What carries an agent's samples, and starting an agent on it: the one place that turns a choice of transport
//! into a running agent, shared by `cortex agent --transport` and the benchmarks that compare transports (`cortex
//! bench payload` measures one path per [`Link`]). A new transport is a new variant here, with its line in
//! [`Link::ALL`], its name and its arm in [`Link::start`]; everything that offers the choice picks it up.

use std::sync::Arc;

use transport::TransportError;
use transport::fault::FaultConfig;
use transport::rtps::RtpsConfig;
use transport::shm::ShmSettings;

use crate::rtps::AgentTransport;
use crate::{Agent, AgentConfig, AgentError};

/// What carries an agent's samples.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Link {
    /// RTPS, with same-host shared memory to the agents of this host and network namespace beside it
    /// ([`crate::rtps::start_hybrid`]); with DDS Security credentials, RTPS alone (shared memory would bypass the
    /// protection). The default.
    Auto,
    /// RTPS (DDS over UDP) alone, any host ([`crate::rtps::start`]).
    Rtps,
    /// Shared memory between the agents of one host, no RTPS ([`crate::shm::start`]): every agent of the graph on
    /// this host and on this link.
    Shm,
}

impl Link {
    /// Every link, in the order command lines list them.
    pub const ALL: [Link; 3] = [Link::Auto, Link::Rtps, Link::Shm];

    /// Its name on command lines (`--transport rtps`).
    pub fn name(self) -> &'static str {
        match self {
            Link::Auto => "auto",
            Link::Rtps => "rtps",
            Link::Shm => "shm",
        }
    }

    /// One line on what it is, for command-line help.
    pub fn summary(self) -> &'static str {
        match self {
            Link::Auto => "RTPS, and shared memory to the agents of this host and network namespace (the default)",
            Link::Rtps => "RTPS (DDS over UDP) alone, any host",
            Link::Shm => "iceoryx2 shared memory alone: every agent of the graph on this host and on `shm`",
        }
    }

    /// The link named `name`, if there is one.
    pub fn from_name(name: &str) -> Option<Link> {
        Link::ALL.into_iter().find(|link| link.name() == name)
    }

    /// Starts an agent of `config` on this link with the real clock. `rtps` names the graph's DDS domain and topic
    /// prefix (shared memory derives its service names from them: [`shm_prefix`]) and, for RTPS, every transport
    /// setting; `faults` as in [`crate::rtps::start`].
    ///
    /// # Errors
    /// [`AgentError::Transport`] when the transport cannot be opened, or when DDS Security's credentials are given
    /// for a link that is not RTPS (they protect RTPS only); otherwise what [`Agent::start`] refuses.
    pub fn start(
        self,
        config: AgentConfig,
        rtps: RtpsConfig,
        faults: Option<FaultConfig>,
    ) -> Result<Arc<Agent<AgentTransport>>, AgentError> {
        match self {
            Link::Auto if rtps.security.is_some() => crate::rtps::start(config, rtps, faults),
            Link::Auto => crate::rtps::start_hybrid(config, rtps, &ShmSettings::default(), faults),
            Link::Rtps => crate::rtps::start(config, rtps, faults),
            Link::Shm => {
                if rtps.security.is_some() {
                    return Err(AgentError::Transport {
                        agent: config.id,
                        source: TransportError::Setup {
                            what: "shared memory".into(),
                            detail: "DDS Security protects RTPS; it does not apply to the shared-memory link".into(),
                        },
                    });
                }
                let prefix = shm_prefix(rtps.domain_id, &rtps.topic_prefix);
                crate::shm::start(config, &prefix, &ShmSettings::default(), faults)
            }
        }
    }
}

impl std::fmt::Display for Link {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// The shared-memory service prefix of the graph on DDS domain `domain` with topic prefix `topic_prefix`:
/// `cortex/d<DOMAIN>/<PREFIX>`.
pub fn shm_prefix(domain: u16, topic_prefix: &str) -> String {
    format!("cortex/d{domain}/{topic_prefix}")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_link_is_found_by_its_own_name_and_no_other() {
        for link in Link::ALL {
            assert_eq!(Link::from_name(link.name()), Some(link));
            assert_eq!(link.to_string(), link.name());
        }
        assert_eq!(Link::from_name("udp"), None);
    }

    #[test]
    fn shared_memory_with_security_credentials_is_refused_with_an_error() {
        let rtps = RtpsConfig {
            security: Some(transport::rtps::SecurityFiles { dir: "/nonexistent".into() }),
            ..RtpsConfig::default()
        };
        let Err(error) = Link::Shm.start(AgentConfig::new(crate::AgentId(1)), rtps, None) else {
            panic!("an agent on shared memory started with DDS Security credentials");
        };
        assert!(error.to_string().contains("DDS Security"), "{error}");
    }

    #[test]
    fn the_shared_memory_prefix_names_domain_and_topic_prefix() {
        assert_eq!(shm_prefix(3, "robot"), "cortex/d3/robot");
    }
}
