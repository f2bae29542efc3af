//! A search/track behaviour written with the BICA FSM support, showing activation changing at run time.
//!
//! - **Search**: states its requirement to [`Attention`] and requires it (so the detectors in charge run);
//!   modulates the [`Scanner`], which sweeps the head. When attention has a target: **Track**.
//! - **Track**: requires [`Attention`] only, which drives the [`Head`](crate::attention::Head) towards the target.
//!   The scanner is no longer stepped: it shuts down quietly (its statistics stop counting runs). When attention
//!   has had no target for `lost_after_ns`: back to **Search**.

use bica::fsm::Fsm;
use bica::prelude::*;

use crate::attention::{Attention, Scanner, StimulusKind};

/// The states.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum SearchTrack {
    /// Looking for the stimulus.
    Search,
    /// Following it.
    Track,
}

/// The behaviour's data: what it looks for.
#[derive(Debug, Clone, PartialEq)]
pub struct SearchTrackData {
    /// The stimulus.
    pub stimulus: StimulusKind,
    /// Priority of the requirement.
    pub priority: u8,
    /// When attention last had a target (step start time, ns).
    pub last_seen_ns: Option<u64>,
}

/// The behaviour component's type.
pub type SearchTrackFsm = Fsm<SearchTrack, SearchTrackData>;

/// Name under which the behaviour states its requirement.
pub const REQUESTER: &str = "search_track";

fn state_requirement(data: &mut SearchTrackData, ctx: &mut StepContext<'_>) -> Result<(), BicaError> {
    ctx.get_mut::<Attention>()?.require(REQUESTER, data.stimulus, data.priority);
    if ctx.get::<Attention>()?.target().is_some() {
        data.last_seen_ns = Some(ctx.step_started_ns());
    }
    Ok(())
}

/// Builds the machine for `stimulus`; it returns to searching after `lost_after_ns` without a target.
///
/// # Errors
/// [`BicaError::InvalidFsm`] (cannot happen for this fixed declaration, but the builder checks).
pub fn search_track(stimulus: StimulusKind, priority: u8, lost_after_ns: u64) -> Result<SearchTrackFsm, BicaError> {
    let data = SearchTrackData { stimulus, priority, last_seen_ns: None };
    Fsm::builder("search_track", SearchTrack::Search, data)
        .state(SearchTrack::Search, |s| {
            s.requires::<Attention>()
                .transition(SearchTrack::Track, |_, ctx, _| ctx.get::<Attention>().is_ok_and(|a| a.target().is_some()))
                .action(state_requirement)
                .modulates::<Scanner>()
        })
        .state(SearchTrack::Track, |s| {
            s.requires::<Attention>()
                .transition(SearchTrack::Search, move |data: &SearchTrackData, ctx, _| {
                    let lost = ctx.get::<Attention>().is_ok_and(|a| a.target().is_none());
                    let since = data.last_seen_ns.map_or(u64::MAX, |t| ctx.step_started_ns().saturating_sub(t));
                    lost && since >= lost_after_ns
                })
                .action(state_requirement)
        })
        .build()
}
