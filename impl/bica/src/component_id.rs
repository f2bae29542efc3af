//! [`ComponentId`]: the index of a registered component, shared by the scheduler core, its errors, traces,
//! statistics and the runtime. It lives apart so that those modules depend on it, not on each other.

use serde::{Deserialize, Serialize};

/// Index of a registered component; stable for the life of the scheduler.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
pub struct ComponentId(pub u32);

impl ComponentId {
    /// The position of the component in the scheduler's tables.
    pub(crate) fn index(self) -> usize {
        self.0 as usize
    }
}
