//! What a campaign writes besides `history.jsonl`: `verdict.json` (settings, episodes, verdict, provenance), the
//! timeline figure (`timeline.svg`/`.png`: faults as bands, each agent's digest agreement over time), and, over
//! several seeds, `summary.json` and `summary.md` with the heal-to-convergence time per fault kind.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::Path;

use anyhow::{Context, Result};
use measure::lanes::{Band, Lane, LaneState, Lanes};
use measure::provenance::Provenance;
use serde::{Deserialize, Serialize};

use super::check::Verdict;
use super::record::{CampaignConfig, EpisodeResult, Recorded, Shown};
use super::schedule::Fault;

/// `verdict.json` of one campaign.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct CampaignReport {
    /// The settings.
    pub config: CampaignConfig,
    /// Whether it passed.
    pub passed: bool,
    /// The verdict on the history.
    pub verdict: Verdict,
    /// The episodes.
    pub episodes: Vec<EpisodeResult>,
    /// Writes by kind of operation.
    pub writes_by_kind: BTreeMap<String, usize>,
    /// Writes the agents skipped (not joined, nothing to operate on).
    pub skipped: u64,
    /// Milliseconds the campaign ran.
    pub duration_ms: f64,
    /// Samples the lives running at the end took from same-host shared memory (zero unless `--same-host`).
    #[serde(default)]
    pub shm_samples_received: u64,
    /// How it was obtained.
    pub provenance: Provenance,
}

impl CampaignReport {
    /// Builds the report; an episode that did not converge is a violation.
    pub fn new(config: CampaignConfig, recorded: &Recorded, mut verdict: Verdict, provenance: Provenance) -> Self {
        for episode in recorded.episodes.iter().filter(|e| e.heal_to_converge_ms.is_none()) {
            verdict.violations.push(format!(
                "no convergence within {} ms after healing \"{}\"",
                config.settle_ms, episode.description
            ));
        }
        verdict.violations.extend(recorded.problems.iter().cloned());
        let mut writes_by_kind = BTreeMap::new();
        for write in &recorded.writes {
            *writes_by_kind.entry(write.op.kind().to_owned()).or_default() += 1;
        }
        CampaignReport {
            config,
            passed: verdict.passed(),
            verdict,
            episodes: recorded.episodes.clone(),
            writes_by_kind,
            skipped: recorded.skipped,
            duration_ms: recorded.duration_ms,
            shm_samples_received: recorded.shm_samples_received,
            provenance,
        }
    }

    /// Writes `verdict.json` and the timeline figure into `dir`.
    ///
    /// # Errors
    /// A file cannot be written.
    pub fn write(&self, dir: &Path, recorded: &Recorded) -> Result<()> {
        let json = serde_json::to_string_pretty(self)?;
        std::fs::write(dir.join("verdict.json"), json).context("writing verdict.json")?;
        measure::lanes::render(&self.figure(recorded), dir, "timeline")
    }

    fn figure(&self, recorded: &Recorded) -> Lanes {
        let states = [
            ("agrees with the majority", (60, 160, 90)),
            ("differs (or no majority)", (220, 70, 60)),
            ("joining", (240, 190, 60)),
            ("paused", (120, 120, 200)),
            ("down", (200, 200, 200)),
        ];
        let index = |shown: Shown| match shown {
            Shown::Agrees => 0,
            Shown::Differs => 1,
            Shown::Joining => 2,
            Shown::Paused => 3,
            Shown::Down => 4,
        };
        let lanes = recorded
            .timeline
            .iter()
            .enumerate()
            .map(|(slot, segments)| Lane {
                name: format!("a{slot}"),
                segments: segments.iter().map(|s| (s.from_ms / 1e3, s.to_ms / 1e3, index(s.shown))).collect(),
            })
            .collect();
        let bands = self
            .episodes
            .iter()
            .map(|e| Band {
                from: e.start_ms / 1e3,
                to: e.heal_ms / 1e3,
                label: match e.heal_to_converge_ms {
                    Some(ms) => format!("{} ({ms:.0} ms)", e.kind),
                    None => format!("{} (no convergence)", e.kind),
                },
            })
            .collect();
        Lanes {
            title: format!(
                "cortex chaos --seed {}: {} ({} writes checked)",
                self.config.seed,
                if self.passed { "converged, nothing lost" } else { "FAILED" },
                self.verdict.writes
            ),
            x_label: "seconds since the campaign started (bands: faults, labelled with heal-to-convergence time)"
                .into(),
            x_range: (0.0, recorded.duration_ms / 1e3),
            states: states.iter().map(|(n, rgb)| LaneState { name: (*n).into(), rgb: *rgb }).collect(),
            lanes,
            bands,
            footer: vec![
                format!("command: {}", self.provenance.command),
                format!(
                    "commit {}, {} build; {}",
                    self.provenance.short_commit(),
                    if self.provenance.release_build { "release" } else { "debug" },
                    self.provenance.machine.summary()
                ),
                format!(
                    "{} agents in network namespaces on one bridge, {} writes/s each, camera frames of {} bytes",
                    self.config.agents, self.config.write_hz, self.config.image_bytes
                ),
            ],
        }
    }
}

/// Per fault kind over several campaigns: heal-to-convergence times.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct KindSummary {
    /// Episodes of the kind.
    pub episodes: usize,
    /// Median milliseconds from heal to convergence (over the episodes that converged).
    pub median_ms: Option<f64>,
    /// Worst.
    pub worst_ms: Option<f64>,
    /// Episodes that did not converge within the settle time.
    pub not_converged: usize,
    /// Median milliseconds from heal until every agent heard every other one.
    pub heard_median_ms: Option<f64>,
    /// Worst.
    pub heard_worst_ms: Option<f64>,
}

/// The median and the worst of `values`.
fn median_and_worst(mut values: Vec<f64>) -> (Option<f64>, Option<f64>) {
    values.sort_by(f64::total_cmp);
    (values.get(values.len() / 2).copied(), values.last().copied())
}

/// `summary.json` over several campaigns.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct Summary {
    /// Seeds run.
    pub seeds: Vec<u64>,
    /// Seeds that failed.
    pub failed: Vec<u64>,
    /// Writes checked over all campaigns.
    pub writes_checked: usize,
    /// Writes of killed lives that never left their process.
    pub lost_with_killed_writer: usize,
    /// Per fault kind.
    pub kinds: BTreeMap<String, KindSummary>,
}

impl Summary {
    /// Summarises `reports`.
    pub fn of(reports: &[CampaignReport]) -> Summary {
        let mut summary = Summary::default();
        let mut times: BTreeMap<String, Vec<f64>> = BTreeMap::new();
        let mut heard: BTreeMap<String, Vec<f64>> = BTreeMap::new();
        for report in reports {
            summary.seeds.push(report.config.seed);
            if !report.passed {
                summary.failed.push(report.config.seed);
            }
            summary.writes_checked += report.verdict.writes;
            summary.lost_with_killed_writer += report.verdict.lost_with_killed_writer;
            for episode in &report.episodes {
                let kind = summary.kinds.entry(episode.kind.clone()).or_default();
                kind.episodes += 1;
                if let Some(ms) = episode.heal_to_heard_ms {
                    heard.entry(episode.kind.clone()).or_default().push(ms);
                }
                match episode.heal_to_converge_ms {
                    Some(ms) => times.entry(episode.kind.clone()).or_default().push(ms),
                    None => kind.not_converged += 1,
                }
            }
        }
        for (kind, values) in times {
            let entry = summary.kinds.entry(kind).or_default();
            (entry.median_ms, entry.worst_ms) = median_and_worst(values);
        }
        for (kind, values) in heard {
            let entry = summary.kinds.entry(kind).or_default();
            (entry.heard_median_ms, entry.heard_worst_ms) = median_and_worst(values);
        }
        summary
    }

    /// A Markdown table.
    pub fn markdown(&self) -> String {
        let mut md = format!(
            "Seeds {:?}: {} passed, {} failed{}; {} writes checked, {} lost with a killed writer (allowed).\n\n",
            self.seeds,
            self.seeds.len() - self.failed.len(),
            self.failed.len(),
            if self.failed.is_empty() { String::new() } else { format!(" ({:?})", self.failed) },
            self.writes_checked,
            self.lost_with_killed_writer
        );
        md.push_str(
            "| fault | episodes | heal → convergence, median | worst | not converged | heal → all peers heard, median \
             | worst |\n|---|---:|---:|---:|---:|---:|---:|\n",
        );
        for kind in Fault::KINDS {
            let Some(k) = self.kinds.get(kind) else { continue };
            let ms = |v: Option<f64>| v.map_or("—".to_owned(), |v| format!("{v:.0} ms"));
            let _ = writeln!(
                md,
                "| {kind} | {} | {} | {} | {} | {} | {} |",
                k.episodes,
                ms(k.median_ms),
                ms(k.worst_ms),
                k.not_converged,
                ms(k.heard_median_ms),
                ms(k.heard_worst_ms)
            );
        }
        md
    }
}
