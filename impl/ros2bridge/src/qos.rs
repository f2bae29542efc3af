//! The QoS ROS 2 uses, as `rustdds` policies: the rmw profiles `rmw_qos_profile_sensor_data` (BEST_EFFORT,
//! VOLATILE, KEEP_LAST 5), `rmw_qos_profile_default` (RELIABLE, VOLATILE, KEEP_LAST 10) and the one
//! `tf2_ros::StaticTransformBroadcaster` and its listeners use for `/tf_static` (RELIABLE, TRANSIENT_LOCAL,
//! KEEP_LAST 1), so that a subscriber that joins late still gets the static transforms.

use rustdds::policy::{Durability, History, Reliability};
use rustdds::{Duration as DdsDuration, QosPolicies, QosPolicyBuilder};
use serde::Deserialize;

/// How long a reliable write may block on a full send window before it fails (and is counted).
const MAX_BLOCKING_MS: i64 = 100;

/// A ROS 2 QoS profile.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum QosProfile {
    /// Sensor data: best effort, volatile, keep last 5.
    Sensor,
    /// The default: reliable, volatile, keep last 10.
    Default,
    /// `/tf_static`: reliable, transient local, keep last 1.
    Static,
}

impl QosProfile {
    /// The name in bridge files and status lines.
    pub fn name(self) -> &'static str {
        match self {
            QosProfile::Sensor => "sensor",
            QosProfile::Default => "default",
            QosProfile::Static => "static",
        }
    }

    /// The `rustdds` policies of this profile (for readers and writers alike).
    pub fn policies(self) -> QosPolicies {
        let reliable = Reliability::Reliable { max_blocking_time: DdsDuration::from_millis(MAX_BLOCKING_MS) };
        let (reliability, durability, depth) = match self {
            QosProfile::Sensor => (Reliability::BestEffort, Durability::Volatile, 5),
            QosProfile::Default => (reliable, Durability::Volatile, 10),
            QosProfile::Static => (reliable, Durability::TransientLocal, 1),
        };
        QosPolicyBuilder::new()
            .reliability(reliability)
            .durability(durability)
            .history(History::KeepLast { depth })
            .build()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_profiles_are_those_of_ros2() {
        let sensor = QosProfile::Sensor.policies();
        assert_eq!(sensor.reliability(), Some(Reliability::BestEffort));
        assert_eq!(sensor.durability(), Some(Durability::Volatile));
        assert_eq!(sensor.history(), Some(History::KeepLast { depth: 5 }));
        let default = QosProfile::Default.policies();
        assert!(matches!(default.reliability(), Some(Reliability::Reliable { .. })));
        assert_eq!(default.history(), Some(History::KeepLast { depth: 10 }));
        let fixed = QosProfile::Static.policies();
        assert_eq!(fixed.durability(), Some(Durability::TransientLocal));
        assert_eq!(fixed.history(), Some(History::KeepLast { depth: 1 }));
    }
}
