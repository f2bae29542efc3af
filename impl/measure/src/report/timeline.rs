//! "Scheduler timeline of a detector under overload": the three-panel figure (achieved frequency, lateness per
//! step with the misses marked, misses and skipped releases so far; the overload window shaded) and a table per
//! phase, from [`crate::results::TimelineResult`]. Says "not run" when the set has no `timeline` section.

use std::fmt::Write as _;
use std::path::Path;

use super::format::footer;
use super::{Context, Section};
use crate::figures::{self, Chart, Panel, Series};
use crate::results::{Results, StepRecord, TimelineResult};
use crate::units::{ms_from_ns, s_from_ms, s_from_ns};

const FIGURE: &str = "scheduler_timeline";

/// The section.
pub(super) const SECTION: Section = Section {
    heading: "## Scheduler timeline of a detector under overload",
    figures: &[FIGURE],
    draw: Some(draw),
    write,
};

/// What the figure's transport line says: this experiment has no network.
const HOW: &str = "none: one BICA runtime on one thread, real monotonic clock, overload injected by another component";

/// Draws the figure: achieved frequency, lateness per step with the misses marked, and misses and skipped releases
/// over time, the overload window shaded in each panel.
fn draw(results: &Results, dir: &Path) -> anyhow::Result<()> {
    let Some(result) = &results.timeline else { return Ok(()) };
    let e = &result.experiment;
    let frame = Panel {
        x_range: Some((0.0, s_from_ms(e.duration_ms))),
        shaded: Some((
            s_from_ms(e.overload_from_ms),
            s_from_ms(e.overload_until_ms),
            format!("overload: {} ms busy every {} ms", e.overload_busy_ms, e.overload_period_ms),
        )),
        ..Panel::default()
    };
    let panels =
        [frequency_panel(result, frame.clone()), lateness_panel(result, frame.clone()), counts_panel(result, frame)];
    figures::render_panels(&panels, &footer(&results.provenance, HOW), dir, FIGURE)
}

/// Achieved frequency over the sliding window, beside the nominal one.
fn frequency_panel(result: &TimelineResult, frame: Panel) -> Panel {
    let e = &result.experiment;
    let nominal_hz = 1e3 / e.period_ms as f64;
    Panel {
        chart: Chart {
            title: format!(
                "{} at {nominal_hz:.0} Hz on the real clock: achieved frequency ({} ms window)",
                short_type(&result.detector),
                e.window_ms
            ),
            x_label: "time (s)".into(),
            y_label: "Hz".into(),
            series: vec![
                Series {
                    name: "achieved".into(),
                    points: result.timeline.frequency.iter().map(|&(t, hz)| (s_from_ns(t), hz)).collect(),
                },
                Series {
                    name: "nominal".into(),
                    points: vec![(0.0, nominal_hz), (s_from_ms(e.duration_ms), nominal_hz)],
                },
            ],
            ..Chart::default()
        },
        ..frame
    }
}

/// Lateness of every step, the misses marked.
fn lateness_panel(result: &TimelineResult, frame: Panel) -> Panel {
    let steps = &result.timeline.steps;
    let point = |s: &StepRecord| (s_from_ns(s.start_ns), ms_from_ns(s.lateness_ns));
    Panel {
        chart: Chart {
            title: "Lateness of each step (start minus release)".into(),
            x_label: "time of the step's start (s)".into(),
            y_label: "ms".into(),
            series: vec![Series { name: "lateness".into(), points: steps.iter().map(point).collect() }],
            legend_upper_left: true,
            ..Chart::default()
        },
        markers: vec![Series {
            name: format!("miss (lateness > {} µs)", result.experiment.miss_tolerance_us),
            points: steps.iter().filter(|s| s.miss).map(point).collect(),
        }],
        ..frame
    }
}

/// Misses and skipped releases so far, drawn as staircases: a count changes at a step's start and holds until the
/// next change.
fn counts_panel(result: &TimelineResult, frame: Panel) -> Panel {
    let mut misses = vec![(0.0, 0.0)];
    let mut skipped = vec![(0.0, 0.0)];
    let (mut m, mut k) = (0.0, 0.0);
    for s in &result.timeline.steps {
        let at = s_from_ns(s.start_ns);
        if s.miss {
            misses.push((at, m));
            m += 1.0;
            misses.push((at, m));
        }
        if s.skipped_releases > 0 {
            skipped.push((at, k));
            k += s.skipped_releases as f64;
            skipped.push((at, k));
        }
    }
    let end = s_from_ms(result.experiment.duration_ms);
    misses.push((end, m));
    skipped.push((end, k));
    Panel {
        chart: Chart {
            title: "Misses and skipped releases so far".into(),
            x_label: "time (s)".into(),
            y_label: "count".into(),
            series: vec![
                Series { name: "misses".into(), points: misses },
                Series { name: "skipped releases".into(), points: skipped },
            ],
            legend_upper_left: true,
            ..Chart::default()
        },
        ..frame
    }
}

fn short_type(name: &str) -> &str {
    name.rsplit("::").next().unwrap_or(name)
}

/// How the timeline was obtained, the figure and a table per phase; with no result (the set has no `timeline`
/// section), says so.
fn write(md: &mut String, results: &Results, _: &Context<'_>) {
    let Some(r) = &results.timeline else {
        let _ = writeln!(md, "Not run: this experiment set has no `timeline` section.\n");
        return;
    };
    let e = &r.experiment;
    let t = &r.timeline;
    let _ = writeln!(
        md,
        "Measured on the **real monotonic clock** (`{}`), one `bica::Runtime` on one thread, not a simulation: the \
         `camera-detector` role of `perception::roles` (camera reader → colour labeller → `{}`, period {} ms) on the \
         {} frames of `{}` (played on their recorded timing, looping, by a `LogCamera` component in the same \
         scheduler), for {} ms. The overload is another component in the same single-threaded scheduler, `{}`, \
         period {} ms, whose steps that start between {} ms and {} ms busy-wait {} ms (it spins on the clock, so it \
         really holds the thread); it is not work inside the detector, so the detector's own cost is unchanged and \
         the figure shows what the scheduler does to the victim of another component's overrun. Every step comes \
         from the bica trace ring (release, start, finish, lateness, skipped releases, miss events; {} events \
         dropped); a miss is a lateness above {} µs. Frequency is the number of steps started in the last {} ms over \
         {} ms. A run of the machine's scheduler, so the numbers vary from run to run.\n",
        r.clock,
        r.detector,
        e.period_ms,
        r.log_frames,
        e.log.display(),
        e.duration_ms,
        r.overload_component,
        e.overload_period_ms,
        e.overload_from_ms,
        e.overload_until_ms,
        e.overload_busy_ms,
        r.trace_dropped,
        e.miss_tolerance_us,
        e.window_ms,
        e.window_ms
    );
    let _ = writeln!(
        md,
        "![scheduler timeline of the detector under overload]({FIGURE}.svg)\n\n(also [{FIGURE}.png]({FIGURE}.png))\n"
    );
    let _ = writeln!(
        md,
        "| phase | from ms | to ms | steps | achieved Hz | lateness mean ms | lateness max ms | misses | skipped releases | step mean ms |\n|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|"
    );
    for p in &t.phases {
        let _ = writeln!(
            md,
            "| {} | {:.0} | {:.0} | {} | {:.1} | {:.3} | {:.3} | {} | {} | {:.3} |",
            p.name,
            ms_from_ns(p.from_ns),
            ms_from_ns(p.until_ns),
            p.steps,
            p.frequency_hz,
            ms_from_ns(p.lateness_mean_ns),
            ms_from_ns(p.lateness_max_ns),
            p.misses,
            p.skipped_releases,
            ms_from_ns(p.step_mean_ns)
        );
    }
    let _ = writeln!(
        md,
        "\nNominal {:.1} Hz. Over the whole run: {} steps, largest lateness {:.3} ms, {} misses, {} skipped releases \
         (never run late as a burst), {} overlapping top-level steps out of {} (no step started before the previous \
         one finished: {}), {} failed steps; the overload busy-waited in {} steps; the scheduler core's own counters \
         (runs {}, misses {}, skipped {}) {} the trace.\n",
        1e3 / e.period_ms as f64,
        t.steps.len(),
        ms_from_ns(t.lateness_max_ns),
        t.misses,
        t.skipped_releases,
        t.overlaps,
        t.top_level_steps,
        if t.overlaps == 0 { "yes" } else { "**no**" },
        r.step_failures,
        r.overload_busy_steps,
        r.counters.runs,
        r.counters.misses,
        r.counters.skipped_releases,
        if r.counters_agree() { "agree with" } else { "**disagree with**" }
    );
}
