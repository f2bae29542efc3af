//! What the trace has shown so far of one registered component: the small summary the trace properties need,
//! built from the trace events alone (never read from the core). It is part of the model's state, so it is kept
//! small and finite: whether the component is in the active list, its release grid (phase and the first time
//! not yet passed by a run), the release its last run served, the last time it was seen, the reactivation gap the
//! trace owes, and the rate limiter's view of its miss warnings.

/// The release grid of a component as the trace defines it: the releases are `r0 + k·T` (k ≥ 0), `r0` being the
/// time of the activation (or first call, or restart after a gap) that started the grid; the grid points before
/// `from_ns` were served or dropped by a run (or precede the grid's origin).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub(super) struct Grid {
    /// `r0 mod T`: the grid points are the times congruent to it (only those from `r0` on matter, and
    /// `from_ns ≥ r0`).
    phase_ns: u64,
    /// Earliest time a pending release may have: `r0`, or one past the start of the last run on the grid.
    from_ns: u64,
}

impl Grid {
    /// The grid starting at `origin_ns` with period `period_ns`.
    fn starting_at(origin_ns: u64, period_ns: u64) -> Self {
        Grid { phase_ns: origin_ns % period_ns, from_ns: origin_ns }
    }

    /// Number of grid points at or before `time_ns` (counting from the phase, so only differences are meaningful).
    fn points_up_to(&self, time_ns: u64, period_ns: u64) -> u64 {
        if time_ns < self.phase_ns { 0 } else { (time_ns - self.phase_ns) / period_ns + 1 }
    }

    /// The oldest release not yet served or dropped: the first grid point at or after `from_ns`.
    pub(super) fn pending_ns(&self, period_ns: u64) -> u64 {
        let offset = (self.phase_ns + period_ns - self.from_ns % period_ns) % period_ns;
        self.from_ns + offset
    }

    /// Whether `time_ns` is a point of the grid (at or after its origin is checked separately, through `from_ns`).
    pub(super) fn contains(&self, time_ns: u64, period_ns: u64) -> bool {
        time_ns % period_ns == self.phase_ns
    }

    /// Number of grid points in `(after_ns, up_to_ns]`: the releases that passed between the two.
    pub(super) fn points_between(&self, after_ns: u64, up_to_ns: u64, period_ns: u64) -> u64 {
        self.points_up_to(up_to_ns, period_ns).saturating_sub(self.points_up_to(after_ns, period_ns))
    }
}

/// The trace's summary of one registered component.
#[derive(Clone, Debug, PartialEq, Eq, Hash, Default)]
pub(super) struct Seen {
    /// In the active list: its last `Activated`/`Deactivated` event was an activation.
    pub(super) active: bool,
    /// Its release grid; `None` until it is first activated or called.
    pub(super) grid: Option<Grid>,
    /// Release served by its last run.
    pub(super) last_release_ns: Option<u64>,
    /// Time of its last step call (`StepStarted` or `GatedSkip`) or `Deactivated` event.
    pub(super) last_seen_ns: Option<u64>,
    /// The gap its next run must report: it was activated (or, not being in the active list, called) more than
    /// k periods after it was last seen, and has not run since.
    pub(super) owed_gap_ns: Option<u64>,
    /// Time of its last miss event with a warning.
    pub(super) last_warning_ns: Option<u64>,
    /// Miss events without a warning since that one.
    pub(super) misses_since_warning: u64,
}

impl Seen {
    /// The oldest pending release, if its grid has started.
    pub(super) fn pending_ns(&self, period_ns: u64) -> Option<u64> {
        self.grid.map(|grid| grid.pending_ns(period_ns))
    }

    /// Restarts the grid at `at_ns`, unless a release of the old grid is still ahead (the old grid then goes on).
    fn restart_grid(&mut self, at_ns: u64, period_ns: u64) {
        let origin = self.pending_ns(period_ns).map_or(at_ns, |pending| pending.max(at_ns));
        self.grid = Some(Grid::starting_at(origin, period_ns));
    }

    /// The gap since the component was last seen, if it is longer than `limit_ns` (k periods).
    fn gap_beyond(&self, at_ns: u64, limit_ns: u64) -> Option<u64> {
        self.last_seen_ns.map(|seen| at_ns.saturating_sub(seen)).filter(|&gap| gap > limit_ns)
    }

    /// An `Activated` event at `at_ns`: the component joins the list, owes a gap if it was away more than
    /// `limit_ns`, and its grid restarts there.
    pub(super) fn activated(&mut self, at_ns: u64, limit_ns: u64, period_ns: u64) {
        self.active = true;
        if let Some(gap) = self.gap_beyond(at_ns, limit_ns) {
            self.owed_gap_ns = Some(gap);
        }
        self.restart_grid(at_ns, period_ns);
    }

    /// A `Deactivated` event at `at_ns`.
    pub(super) fn deactivated(&mut self, at_ns: u64) {
        self.active = false;
        self.last_seen_ns = Some(at_ns);
    }

    /// A step call at `at_ns` (run or gated skip), before its outcome is looked at: a component outside the
    /// active list starts its grid at its first call, and after a gap of more than `limit_ns` owes the gap and
    /// restarts its grid (idleness is not lateness).
    pub(super) fn called(&mut self, at_ns: u64, limit_ns: u64, period_ns: u64) {
        if self.grid.is_none() {
            self.grid = Some(Grid::starting_at(at_ns, period_ns));
        } else if !self.active
            && let Some(gap) = self.gap_beyond(at_ns, limit_ns)
        {
            self.owed_gap_ns = Some(gap);
            self.restart_grid(at_ns, period_ns);
        }
        self.last_seen_ns = Some(at_ns);
    }

    /// A run that started at `at_ns` serving `release_ns`: every grid point up to its start is now served or
    /// dropped.
    pub(super) fn ran(&mut self, at_ns: u64, release_ns: u64) {
        if let Some(grid) = &mut self.grid {
            grid.from_ns = grid.from_ns.max(at_ns.saturating_add(1));
        }
        self.last_release_ns = Some(release_ns);
        self.owed_gap_ns = None;
    }

    /// A miss event at `at_ns`, with or without a warning.
    pub(super) fn missed(&mut self, at_ns: u64, warned: bool) {
        if warned {
            self.last_warning_ns = Some(at_ns);
            self.misses_since_warning = 0;
        } else {
            self.misses_since_warning += 1;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::Grid;

    #[test]
    fn the_pending_release_is_the_first_grid_point_not_yet_passed() {
        let mut grid = Grid::starting_at(3, 10);
        assert_eq!(grid.pending_ns(10), 3);
        grid.from_ns = 4;
        assert_eq!(grid.pending_ns(10), 13);
        grid.from_ns = 13;
        assert_eq!(grid.pending_ns(10), 13);
        grid.from_ns = 26;
        assert_eq!(grid.pending_ns(10), 33);
    }

    #[test]
    fn points_between_counts_the_grid_points_in_a_half_open_interval() {
        let grid = Grid::starting_at(3, 10);
        assert_eq!(grid.points_between(3, 3, 10), 0);
        assert_eq!(grid.points_between(3, 12, 10), 0);
        assert_eq!(grid.points_between(3, 13, 10), 1);
        assert_eq!(grid.points_between(3, 35, 10), 3);
        assert_eq!(grid.points_between(0, 2, 10), 0);
        assert!(grid.contains(23, 10) && !grid.contains(24, 10));
    }
}
