//! `cortex report`: run an experiment set and write a paper-style report.
//!
//! Reads an experiment file (`experiments/paper.toml` by default; TOML, see `measure::experiment`), runs its
//! `quick` set (the default, at most 5 minutes on 2 cores) or its `full` sweep (`--full`) with a progress bar, and
//! writes into `--out` (default `reports/<name>-<mode>`): `results.json` (versioned schema with commit, rustc,
//! machine, seeds and dataset checksums), the figures as SVG and PNG, one MCAP recording per run under `runs/`
//! (metrics on JSON-schema channels, for Foxglove; `measure::record`) and `report.md`. Each figure and table says
//! which transport it used (in process, or receivers as separate processes) and on which network (`--netns`: by
//! default the whole report re-runs itself in a fresh network namespace with a multicast-capable loopback).

use std::path::PathBuf;

use anyhow::Context as _;
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};
use measure::experiment::{ExperimentFile, run_set};
use std::io::IsTerminal as _;
use std::time::Instant;

/// Arguments of `cortex report`.
#[derive(Debug, Args)]
pub struct ReportArgs {
    /// The experiment file.
    #[arg(long, default_value = "experiments/paper.toml")]
    config: PathBuf,
    /// Directory of the report (created; files in it are replaced). Default: `reports/<name>-<quick|full>`.
    #[arg(long)]
    out: Option<PathBuf>,
    /// Run the file's quick set (the default).
    #[arg(long, conflicts_with = "full")]
    quick: bool,
    /// Run the file's whole sweep.
    #[arg(long)]
    full: bool,
    /// Run the whole report in a fresh network namespace whose loopback is multicast-capable (root, `unshare` and
    /// `ip`): the loopback counters then count only the report's traffic, and RTPS sends one multicast datagram
    /// for all same-host readers, as the paper's configuration does. `auto` falls back to the host's network with
    /// a note; the report says which it was.
    #[arg(long, value_enum, default_value_t = super::bench::NetnsMode::Auto)]
    netns: super::bench::NetnsMode,
}

/// Progress of a long report: a bar on a terminal; elsewhere (a log file, CI) one line per finished run on
/// standard error, so a log shows what ran, how long it took and what is left.
enum Progress {
    Bar(ProgressBar),
    Lines { total: u64, done: u64, started: Instant, last: Instant },
}

impl Progress {
    fn new(total: u64, title: &str) -> anyhow::Result<Progress> {
        if !std::io::stderr().is_terminal() {
            let now = Instant::now();
            eprintln!("{title}: {total} runs");
            return Ok(Progress::Lines { total, done: 0, started: now, last: now });
        }
        let bar = ProgressBar::new(total);
        bar.set_style(
            ProgressStyle::with_template("{elapsed_precise} [{bar:30}] {pos}/{len} runs  {msg}")
                .context("progress bar template")?
                .progress_chars("=> "),
        );
        bar.set_message(title.to_owned());
        Ok(Progress::Bar(bar))
    }

    /// The run `label` finished.
    fn step(&mut self, label: &str) {
        match self {
            Progress::Bar(bar) => {
                bar.inc(1);
                bar.set_message(label.to_owned());
            }
            Progress::Lines { total, done, started, last } => {
                *done += 1;
                let now = Instant::now();
                eprintln!(
                    "run {done}/{total} ({label}) took {:.1} s; {:.0} s in all, {} left",
                    (now - *last).as_secs_f64(),
                    (now - *started).as_secs_f64(),
                    *total - (*done).min(*total),
                );
                *last = now;
            }
        }
    }

    fn finish(self) {
        if let Progress::Bar(bar) = self {
            bar.finish_and_clear();
        }
    }
}

/// Runs `cortex report`.
///
/// # Errors
/// An experiment file that cannot be read or parsed, a log that cannot be read, a failed run, or a report that
/// cannot be written.
pub fn run(args: ReportArgs) -> anyhow::Result<()> {
    use super::bench::NetnsMode;
    if measure::netns::inside().is_none() && args.netns != NetnsMode::Off {
        match measure::netns::reexec_in_fresh_netns(measure::netns::NetnsSetup { multicast: true }) {
            Ok(status) if status.success() => return Ok(()),
            Ok(status) => anyhow::bail!("the report in a fresh network namespace failed ({status})"),
            Err(error) if args.netns == NetnsMode::Require => {
                return Err(error).context("--netns require: cannot run in a fresh network namespace");
            }
            Err(error) => eprintln!(
                "note: no fresh network namespace ({error}); the report runs on the host's network, its loopback \
                 counters include other traffic"
            ),
        }
    }
    let file = ExperimentFile::load(&args.config)?;
    let root = ExperimentFile::root_of(&args.config);
    let (mode, set) = if args.full { ("full", &file.full) } else { ("quick", &file.quick) };
    let out = args.out.unwrap_or_else(|| root.join("reports").join(format!("{}-{mode}", file.name)));
    let mut progress = Progress::new(set.steps(), &format!("{} ({mode})", file.name))?;
    let program = std::env::current_exe().context("cannot find the cortex binary to start receiver processes")?;
    let results = run_set(set, &root, &file.name, mode, Some(&program), &mut |label| progress.step(label))?;
    progress.finish();
    measure::report::write(&results, &out)?;
    println!(
        "report {} ({mode}): {} runs in {:.1} s, written to {}",
        file.name,
        set.steps(),
        results.seconds,
        out.join("report.md").display()
    );
    Ok(())
}
