//! How a state of the agents model prints in a counterexample: each agent's life, replica and digest, then what is
//! in flight, the writes, the findings and the cut.

use std::fmt;

use super::AgentsState;

impl fmt::Debug for AgentsState {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for (index, slot) in self.slots.iter().enumerate() {
            match &slot.core {
                None => writeln!(f, "agent {index}: crashed (record {:?})", slot.record)?,
                Some(core) => match core.replica() {
                    Some(r) => writeln!(
                        f,
                        "agent {index} life {} at {} ms: replica {}, {} nodes, digest {}, applied {:?}",
                        slot.lives,
                        slot.now_ns / 1_000_000,
                        r.id(),
                        r.node_count(),
                        r.digest(),
                        r.applied().version_vector()
                    )?,
                    None => {
                        writeln!(f, "agent {index} life {} at {} ms: joining", slot.lives, slot.now_ns / 1_000_000)?
                    }
                },
            }
        }
        for envelope in &self.network {
            let kind = agent::envelope::Envelope::decode(&envelope.bytes).map(|e| e.message.kind()).unwrap_or("?");
            writeln!(f, "  in flight: {kind} {} -> {}", envelope.from, envelope.to)?;
        }
        for op in &self.history {
            writeln!(f, "  write: {op}")?;
        }
        for finding in &self.findings {
            writeln!(f, "  FOUND: {finding}")?;
        }
        if let Some(cut) = self.cut {
            writeln!(f, "  cut: {cut:#b}")?;
        }
        Ok(())
    }
}
