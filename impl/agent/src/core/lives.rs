//! Lives and their ids: this life's incarnation (above every one seen and the recorded one), and id collisions
//! (another life of this agent id, or a reuse of this life's replica id). See the [`super`] documentation, "Lives".

use dsr::{CausalContext, Replica, ReplicaId};

use super::{AgentCore, Event, INCARNATION_LIMIT, Output, RANDOM_FLOOR_LIMIT};
use crate::AgentId;
use crate::mutants::ProtocolMutant;

impl AgentCore {
    /// Raises the incarnation floor to every incarnation of this agent id in `context`, and reports a reuse of
    /// this life's replica id.
    pub(super) fn note_incarnations(&mut self, context: &CausalContext, out: &mut Output) {
        let me = self.config.id;
        for replica in context.replicas() {
            if AgentId::of_replica(replica) == me {
                self.incarnation_floor = self.incarnation_floor.max(AgentId::incarnation_of(replica));
            }
        }
        if let Some(detail) = self.replica.as_ref().and_then(|mine| reused_id(mine, context))
            && self.collision.is_none()
        {
            self.collide(detail, out);
        }
    }

    fn collide(&mut self, detail: String, out: &mut Output) {
        out.events.push(Event::Collision { detail: detail.clone() });
        self.collision = Some(detail);
    }

    /// Whether a message with this agent's id from life `nonce` (replica `replica`, if known) is a collision: a
    /// message of another life not older than this one.
    pub(super) fn check_collision(&mut self, nonce: u64, replica: Option<ReplicaId>, kind: &str, out: &mut Output) {
        if nonce == self.life.nonce || self.collision.is_some() {
            return;
        }
        let mine = self.replica.as_ref().map(|r| AgentId::incarnation_of(r.id()));
        let older = match (replica, mine) {
            (Some(theirs), Some(mine)) => AgentId::incarnation_of(theirs) < mine,
            _ => false,
        };
        if !older {
            let detail = format!(
                "a {kind} from another life of {} (nonce {nonce:#x}, mine {:#x})",
                self.config.id, self.life.nonce
            );
            self.collide(detail, out);
        }
    }

    /// This life's incarnation: above every one seen and the recorded one (or a random floor without a record).
    pub(super) fn incarnation(&self) -> Option<u32> {
        if self.config.plant.is(ProtocolMutant::IncarnationForgotten) {
            // Only what peers showed counts: a life that starts alone reuses the first life's id.
            return Some(self.incarnation_floor + 1);
        }
        let floor = match self.life.recorded_incarnation {
            Some(recorded) => recorded,
            None => (self.life.nonce % u64::from(RANDOM_FLOOR_LIMIT)) as u32,
        };
        let incarnation = self.incarnation_floor.max(floor).checked_add(1)?;
        (incarnation < INCARNATION_LIMIT).then_some(incarnation)
    }
}

/// Whether `context` holds operations of `replica`'s own id that it did not make (an earlier life used the id).
pub(super) fn reused_id(replica: &Replica, context: &CausalContext) -> Option<String> {
    let id = replica.id();
    let (held, made) = (context.version(id), replica.applied().version(id));
    (held > made).then(|| {
        format!(
            "a peer holds {held} operations of replica {id}, this life's id, which made {made}: an earlier life used it"
        )
    })
}
