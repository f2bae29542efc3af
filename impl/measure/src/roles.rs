//! Detector roles during a replay over RTPS: a log played by a bridge agent into `cortex agent` processes running
//! BICA roles (camera detector, laser detector, attention), optionally with faults injected where they receive.
//! It calls the RTPS replay runner ([`crate::replay_rtps::run`]; the `cortex` binary given to
//! [`crate::experiment::run_set`] runs the agent processes) and keeps what the replay reports: every role's BICA
//! statistics (frequency achieved, misses, skipped releases, lateness and step time, fetched by a remote call over
//! the same DDS engine just before the roles are quiesced), each agent's graph, and the time from the quiesce —
//! when every writer has stopped — until every agent had the bridge's digest (sampled from status lines every
//! 100 ms, so that is its resolution). The statistics calls come between the end of the replay and the quiesce;
//! with injected loss a lost call waits out its 1 s timeout, which is why the window is counted from the quiesce.

use std::path::Path;
use std::time::Duration;

use anyhow::{Context as _, anyhow};
use transport::fault::FaultConfig;

use crate::replay_rtps::{self, RoleSpec, RtpsReplay};
use crate::results::RolesResult;
use crate::spec::RolesExperiment;

pub use crate::results::{AgentRow, ComponentRow};

/// How long the agents get to be ready, and after the replay to converge (`cortex replay`'s default).
const SETTLE: Duration = Duration::from_secs(30);

/// Runs the roles replay on DDS domain `domain`, its agent processes started with `program` (the `cortex` binary).
///
/// # Errors
/// The experiment's log, rate, roles or faults are invalid, the replay fails, or the agents' final digests differ.
pub fn run(experiment: &RolesExperiment, root: &Path, program: &Path, domain: u16) -> anyhow::Result<RolesResult> {
    let settings = settings(experiment, program, domain)?;
    let path = root.join(&experiment.log.path);
    let log = replay::Log::open(&path, replay::ReadOptions::default())
        .with_context(|| format!("cannot replay {}", path.display()))?;
    let outcome = replay_rtps::run(&log, &settings)?;
    if !outcome.digests_equal {
        let digests: Vec<&str> = outcome.agents.iter().map(|a| a.digest.as_str()).collect();
        anyhow::bail!("the agents' final digests differ: {}", digests.join(" "));
    }
    Ok(outcome.roles_result(settings.faults.as_ref()))
}

/// The runner's settings for `experiment`: its rate, roles and faults parsed (faults that inject nothing are none).
fn settings(experiment: &RolesExperiment, program: &Path, domain: u16) -> anyhow::Result<RtpsReplay> {
    let rate = experiment.log.rate.parse().map_err(|e| anyhow!("roles experiment field `log.rate`: {e}"))?;
    let roles = experiment
        .roles
        .iter()
        .map(|name| name.parse::<RoleSpec>().map_err(|e| anyhow!("roles experiment field `roles`: {e}")))
        .collect::<anyhow::Result<_>>()?;
    let faults = match &experiment.faults {
        Some(text) => {
            let faults: FaultConfig = text.parse().map_err(|e| anyhow!("roles experiment field `faults`: {e}"))?;
            Some(faults).filter(|f| *f != FaultConfig::default())
        }
        None => None,
    };
    Ok(RtpsReplay {
        agents: experiment.agents,
        domain,
        roles,
        faults,
        bridge: replay::BridgeOptions::default(),
        rate,
        loops: experiment.log.loops,
        settle: SETTLE,
        record: None,
        program: program.to_owned(),
        // `cortex report` draws its progress on standard error.
        quiet_agents: true,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::spec::LogSpec;

    fn experiment(roles: &[&str], faults: Option<&str>) -> RolesExperiment {
        RolesExperiment {
            log: LogSpec { path: "log.mcap".into(), rate: "2".to_owned(), loops: 3 },
            agents: 4,
            roles: roles.iter().map(|r| (*r).to_owned()).collect(),
            faults: faults.map(str::to_owned),
        }
    }

    #[test]
    fn an_experiment_gives_the_runner_its_roles_rate_loops_and_faults() {
        let settings = settings(
            &experiment(&["camera-detector:cam0", "attention"], Some("loss=0.1")),
            Path::new("/bin/cortex"),
            7,
        )
        .unwrap();
        assert_eq!((settings.agents, settings.domain, settings.loops), (4, 7, 3));
        assert_eq!(settings.rate, replay::Rate::Factor(2.0));
        assert_eq!(settings.roles, vec!["camera-detector:cam0".parse().unwrap(), "attention".parse().unwrap()]);
        assert_eq!(settings.faults.map(|f| f.to_spec()), Some("loss=0.1".parse::<FaultConfig>().unwrap().to_spec()));
        assert_eq!(settings.program, Path::new("/bin/cortex"));
        assert_eq!(settings.settle, SETTLE);
    }

    #[test]
    fn faults_that_inject_nothing_are_no_faults() {
        let settings = settings(&experiment(&[], Some("none")), Path::new("cortex"), 0).unwrap();
        assert_eq!(settings.faults, None);
    }

    #[test]
    fn a_bad_role_or_fault_names_the_experiment_field() {
        let error = settings(&experiment(&["painter"], None), Path::new("cortex"), 0).unwrap_err().to_string();
        assert!(error.contains("`roles`") && error.contains("not a role"), "{error}");
        let error = settings(&experiment(&[], Some("los=1")), Path::new("cortex"), 0).unwrap_err().to_string();
        assert!(error.contains("`faults`"), "{error}");
    }
}
