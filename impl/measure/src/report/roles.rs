//! "Detector roles over RTPS": the roles replay's command, its convergence, and every role component's BICA
//! statistics, from [`crate::results::RolesResult`]. Says "not run" when the set has no `roles` section.

use std::fmt::Write as _;

use super::{Context, Section};
use crate::results::{Results, RolesResult};
use crate::spec::RolesExperiment;

/// The section.
pub(super) const SECTION: Section = Section { heading: "## Detector roles over RTPS", figures: &[], draw: None, write };

/// A type name without its module paths: `perception::sensors::SensorReader<perception::sensors::Camera>` →
/// `SensorReader<Camera>`.
pub(super) fn short_type_name(name: &str) -> String {
    let mut out = String::with_capacity(name.len());
    let mut token = String::new();
    let flush = |token: &mut String, out: &mut String| {
        out.push_str(token.rsplit("::").next().unwrap_or(token));
        token.clear();
    };
    for c in name.chars() {
        if c.is_alphanumeric() || c == '_' || c == ':' {
            token.push(c);
        } else {
            flush(&mut token, &mut out);
            out.push(c);
        }
    }
    flush(&mut token, &mut out);
    out
}

/// The replay's command, how it ran and a row per role component (nothing to say beyond "not run" when the set
/// has no `roles` section).
fn write(md: &mut String, results: &Results, _: &Context<'_>) {
    section(md, results.set.roles.as_ref(), results.roles.as_ref());
}

fn section(md: &mut String, experiment: Option<&RolesExperiment>, result: Option<&RolesResult>) {
    let (Some(e), Some(r)) = (experiment, result) else {
        let _ = writeln!(md, "Not run: this experiment set has no `roles` section.\n");
        return;
    };
    let _ = writeln!(
        md,
        "`cortex replay {} --transport rtps --agents {} --roles {} --rate {}{}`: the bridge agent (this process) plays \
         the log into {} `cortex agent` processes over RTPS, each a real agent (envelope, anti-entropy) running its \
         BICA role on the real clock; {}. After the replay the bridge fetches every role's BICA statistics by a \
         remote call (`runtime.components`), tells the roles to stop writing, and waits until every agent shows its \
         digest: {} ({} messages, {} deltas in {:.2} s).\n",
        e.log.path.display(),
        e.agents,
        e.roles.join(","),
        e.log.rate,
        e.faults.as_ref().map_or_else(String::new, |f| format!(" --faults {f}")),
        e.agents - 1,
        r.faults.as_ref().map_or_else(
            || "no faults injected".to_owned(),
            |f| format!("faults injected into what each agent process receives: `{f}`")
        ),
        match (r.digests_equal, r.converged_ms) {
            (true, Some(ms)) => format!(
                "every digest equal {ms:.0} ms after the writers stopped (100 ms resolution; the roles were told to \
                 stop writing {:.0} ms after the replay ended, once their statistics were fetched)",
                r.quiesced_after_ms.unwrap_or(0.0)
            ),
            _ => "**the digests did not become equal** within the settle time".to_owned(),
        },
        r.messages,
        r.deltas,
        r.seconds
    );
    let _ = writeln!(
        md,
        "Lateness is measured against each component's own release grid. A component stepped by its parent in the \
         cascade (the camera reader and colour labeller under the blob detector; the stimuli and head under the \
         search/track behaviour) runs when its parent runs, so a phase offset of up to one parent period shows as \
         lateness and misses there; the top of each cascade shows the scheduler's own lateness.\n"
    );
    let _ = writeln!(
        md,
        "| agent | role | nodes | samples received | component | achieved / nominal Hz | runs | misses | skipped | lateness p99 ms | step p99 ms |\n|---:|---|---:|---:|---|---:|---:|---:|---:|---:|---:|"
    );
    for a in &r.agents {
        if a.components.is_empty() {
            let note =
                a.components_error.as_deref().map_or("—".to_owned(), |e| format!("statistics unavailable: {e}"));
            let _ =
                writeln!(md, "| {} | {} | {} | {} | {note} | | | | | | |", a.id, a.role, a.nodes, a.samples_received);
        }
        for c in &a.components {
            let _ = writeln!(
                md,
                "| {} | {} | {} | {} | `{}` | {:.1} / {:.1} | {} | {} | {} | {:.2} | {:.2} |",
                a.id,
                a.role,
                a.nodes,
                a.samples_received,
                short_type_name(&c.name),
                c.achieved_hz,
                c.nominal_hz,
                c.runs,
                c.misses,
                c.skipped_releases,
                c.lateness_p99_ms,
                c.wall_p99_ms
            );
        }
    }
    let _ = writeln!(md);
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::spec::LogSpec;

    #[test]
    fn a_replay_summary_parses_into_the_result_and_the_section_shows_it() {
        let json = r#"{"file":"x.mcap","transport":"rtps","agents":2,"messages":10,"deltas":12,"seconds":1.5,
            "digests_equal":true,"converged_ms":120.5,"faults":"loss=0.1",
            "agent_reports":[{"id":1,"role":"bridge","nodes":5,"digest":"ab","samples_received":3,"samples_sent":9},
              {"id":2,"role":"camera-detector","nodes":5,"digest":"ab","samples_received":12,"samples_sent":2,
               "components":[{"name":"perception::blobs::BlobDetector","nominal_hz":10.0,"achieved_hz":9.9,"runs":15,
                 "misses":1,"skipped_releases":0,"lateness_p99_ms":0.5,"wall_p99_ms":0.1}]}]}"#;
        let result: RolesResult = serde_json::from_str(json).unwrap();
        assert_eq!(result.agents.len(), 2);
        assert_eq!(result.agents[1].components[0].runs, 15);
        let experiment = RolesExperiment {
            log: LogSpec { path: "x.mcap".into(), rate: "1".into(), loops: 1 },
            agents: 2,
            roles: vec!["camera-detector".into()],
            faults: Some("loss=0.1".into()),
        };
        let mut md = String::new();
        section(&mut md, Some(&experiment), Some(&result));
        assert!(
            md.contains("| 2 | camera-detector | 5 | 12 | `BlobDetector` | 9.9 / 10.0 | 15 | 1 | 0 | 0.50 | 0.10 |"),
            "{md}"
        );
        assert!(md.contains("every digest equal 120 ms after the writers stopped"), "{md}");
        assert_eq!(
            short_type_name("bica::fsm::Fsm<perception::behaviour::SearchTrack, perception::behaviour::Data>"),
            "Fsm<SearchTrack, Data>"
        );
        assert_eq!(short_type_name("Plain"), "Plain");
        let mut md = String::new();
        section(&mut md, None, None);
        assert!(md.contains("Not run"));
    }
}
