//! Running a Stateright checker and reporting what it found, in one format for every model.
//!
//! A [`CheckReport`] carries the configuration, the search figures (states explored, unique states, depth,
//! seconds, states per second, whether the search finished) and, for each property, whether it holds and, if not,
//! a counterexample: the sequence of actions from the initial state and the state reached. `cortex check` prints it
//! as text or as JSON.

use std::fmt::Debug;
use std::hash::Hash;
use std::time::{Duration, Instant};

use serde::Serialize;
use stateright::report::{ReportData, ReportDiscovery, Reporter};
use stateright::{Checker, Expectation, Model};

/// How the checker searches.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Search {
    /// Depth-first (the fast exhaustive mode).
    Dfs,
    /// Breadth-first (shortest counterexamples).
    Bfs,
}

/// Options for one checker run.
#[derive(Clone, Debug)]
pub struct CheckOptions {
    /// Search strategy.
    pub search: Search,
    /// Worker threads.
    pub threads: usize,
    /// Stop after this long (the report then says the search is incomplete).
    pub timeout: Option<Duration>,
    /// Print a progress line to standard error while checking.
    pub progress: bool,
}

impl Default for CheckOptions {
    fn default() -> Self {
        CheckOptions { search: Search::Dfs, threads: 2, timeout: None, progress: false }
    }
}

/// The verdict on one property.
#[derive(Clone, Debug, Serialize)]
pub struct PropertyResult {
    /// Property name.
    pub name: String,
    /// `always`, `sometimes` or `eventually`.
    pub expectation: String,
    /// For `always`/`eventually`: no counterexample was found. For `sometimes`: an example was found.
    pub holds: bool,
    /// The path that violates an `always`/`eventually` property (or witnesses a `sometimes` one).
    pub path: Option<CounterExample>,
}

/// A path through the model: the actions taken from the initial state, and the state reached.
#[derive(Clone, Debug, Serialize)]
pub struct CounterExample {
    /// The actions, in order.
    pub actions: Vec<String>,
    /// The last state, pretty-printed.
    pub last_state: String,
}

/// The result of one checker run.
#[derive(Clone, Debug, Serialize)]
pub struct CheckReport {
    /// Which model.
    pub model: String,
    /// Its configuration.
    pub configuration: serde_json::Value,
    /// Search strategy.
    pub search: Search,
    /// Worker threads.
    pub threads: usize,
    /// States generated, repeats included.
    pub states_explored: usize,
    /// Distinct states.
    pub unique_states: usize,
    /// Deepest path explored.
    pub max_depth: usize,
    /// Wall-clock seconds of the search.
    pub seconds: f64,
    /// States explored per second.
    pub states_per_second: f64,
    /// Whether every reachable state was visited (false if the timeout cut the search).
    pub complete: bool,
    /// One verdict per property.
    pub properties: Vec<PropertyResult>,
}

impl CheckReport {
    /// Whether every property holds (`always`/`eventually` unviolated, `sometimes` witnessed).
    pub fn all_hold(&self) -> bool {
        self.properties.iter().all(|p| p.holds)
    }

    /// The properties that do not hold.
    pub fn failures(&self) -> impl Iterator<Item = &PropertyResult> {
        self.properties.iter().filter(|p| !p.holds)
    }

    /// A human-readable summary.
    pub fn to_text(&self) -> String {
        let mut out = format!(
            "model {}: {} states explored, {} unique, depth {}, {:.2} s, {:.0} states/s{}\n",
            self.model,
            self.states_explored,
            self.unique_states,
            self.max_depth,
            self.seconds,
            self.states_per_second,
            if self.complete { "" } else { " (INCOMPLETE: timed out)" }
        );
        for property in &self.properties {
            let verdict = if property.holds { "holds" } else { "FAILS" };
            out.push_str(&format!("  {:<10} {:<60} {verdict}\n", property.expectation, property.name));
            if let (false, Some(path)) = (property.holds, &property.path) {
                out.push_str("    counterexample:\n");
                for (index, action) in path.actions.iter().enumerate() {
                    out.push_str(&format!("      {:>3}. {action}\n", index + 1));
                }
                out.push_str(&format!("    reaching state:\n{}\n", indent(&path.last_state, 6)));
            }
        }
        out
    }
}

fn indent(text: &str, spaces: usize) -> String {
    let pad = " ".repeat(spaces);
    text.lines().map(|line| format!("{pad}{line}")).collect::<Vec<_>>().join("\n")
}

/// Polls the checker every 20 ms (the resolution of the reported search time) and prints a progress line to
/// standard error at most once a second.
struct ProgressLine {
    enabled: bool,
    last_printed: Option<Instant>,
}

impl<M: Model> Reporter<M> for ProgressLine {
    fn delay(&self) -> Duration {
        Duration::from_millis(20)
    }

    fn report_checking(&mut self, data: ReportData) {
        let due = self.last_printed.is_none_or(|at| at.elapsed() >= Duration::from_secs(1));
        if self.enabled && (due || data.done) {
            self.last_printed = Some(Instant::now());
            eprintln!(
                "  … {} states explored, {} unique, depth {}, {:.1} s{}",
                data.total_states,
                data.unique_states,
                data.max_depth,
                data.duration.as_secs_f64(),
                if data.done { " (done)" } else { "" }
            );
        }
    }

    fn report_discoveries(
        &mut self,
        _model: &M,
        _discoveries: std::collections::BTreeMap<&'static str, ReportDiscovery<M>>,
    ) where
        M::Action: Debug + PartialEq,
        M::State: Debug + Hash + PartialEq,
    {
    }
}

/// Runs the checker on `model` and turns what it found into a report.
pub fn run_check<M>(model: M, name: &str, configuration: serde_json::Value, options: &CheckOptions) -> CheckReport
where
    M: Model + Send + Sync + 'static,
    M::State: Clone + Debug + Hash + PartialEq + Send + Sync + 'static,
    M::Action: Clone + Debug + PartialEq + Send + Sync + 'static,
{
    let properties = model.properties();
    let mut builder = model.checker().threads(options.threads.max(1));
    if let Some(timeout) = options.timeout {
        builder = builder.timeout(timeout);
    }
    let started = Instant::now();
    let mut progress = ProgressLine { enabled: options.progress, last_printed: None };
    match options.search {
        Search::Dfs => {
            let checker = builder.spawn_dfs().join_and_report(&mut progress);
            summarize(checker, &properties, started, name, configuration, options)
        }
        Search::Bfs => {
            let checker = builder.spawn_bfs().join_and_report(&mut progress);
            summarize(checker, &properties, started, name, configuration, options)
        }
    }
}

fn summarize<M, C>(
    checker: C,
    properties: &[stateright::Property<M>],
    started: Instant,
    name: &str,
    configuration: serde_json::Value,
    options: &CheckOptions,
) -> CheckReport
where
    M: Model,
    M::State: Clone + Debug + Hash + PartialEq,
    M::Action: Clone + Debug + PartialEq,
    C: Checker<M>,
{
    let seconds = started.elapsed().as_secs_f64();
    let discoveries = checker.discoveries();
    let model = checker.model();
    let results = properties
        .iter()
        .map(|property| {
            let found = discoveries.get(property.name);
            let expectation = match property.expectation {
                Expectation::Always => "always",
                Expectation::Sometimes => "sometimes",
                Expectation::Eventually => "eventually",
            };
            let holds = match property.expectation {
                Expectation::Sometimes => found.is_some(),
                Expectation::Always | Expectation::Eventually => found.is_none(),
            };
            let path = found.map(|path| CounterExample {
                actions: path.clone().into_actions().iter().map(|a| model.format_action(a)).collect(),
                last_state: format!("{:#?}", path.last_state()),
            });
            PropertyResult { name: property.name.to_owned(), expectation: expectation.to_owned(), holds, path }
        })
        .collect();
    let states_explored = checker.state_count();
    CheckReport {
        model: name.to_owned(),
        configuration,
        search: options.search,
        threads: options.threads,
        states_explored,
        unique_states: checker.unique_state_count(),
        max_depth: checker.max_depth(),
        seconds,
        states_per_second: if seconds > 0.0 { states_explored as f64 / seconds } else { 0.0 },
        complete: checker.is_done() && options.timeout.is_none_or(|t| started.elapsed() < t),
        properties: results,
    }
}
