//! [`GraphId`]: which graph an agent belongs to.
//!
//! Agents of several graphs can share one DDS domain and topic prefix (two labs' robots on one network with the
//! defaults). Every envelope carries its sender's graph id (see [`crate::envelope`]), and the protocol core refuses
//! a message of another graph: it is counted, and reported once per foreign graph id, never merged (see
//! [`crate::core`], **Graphs**).
//!
//! A graph's id is chosen when the graph is created: given by its creator (`cortex agent --graph-id`), or drawn
//! from the creating life's random nonce ([`GraphId::from_nonce`]) when it starts alone without one and heard no
//! agent of a graph while it waited. A joiner that names no graph takes the id of the graph it joins, or, starting
//! alone after hearing agents of one graph, that graph's. Written as 16 lower-case hexadecimal digits; never zero (zero
//! on the wire means "no graph yet", which only a joiner's graph request may say).

use std::fmt;
use std::str::FromStr;

/// The id of one graph: a non-zero 64-bit number, shown as 16 hexadecimal digits.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct GraphId(u64);

/// Why a text is not a graph id.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum GraphIdError {
    /// Not 1 to 16 hexadecimal digits.
    #[error("graph id {0:?} is not 1 to 16 hexadecimal digits")]
    NotHex(String),
    /// Zero is reserved (it means "no graph yet" on the wire).
    #[error("graph id 0 is reserved (it means \"no graph yet\")")]
    Zero,
}

impl GraphId {
    /// The graph id `value`; `None` for zero (reserved).
    pub const fn new(value: u64) -> Option<GraphId> {
        if value == 0 { None } else { Some(GraphId(value)) }
    }

    /// The number.
    pub fn get(self) -> u64 {
        self.0
    }

    /// The id of a graph created by a life with this random nonce (a bijective mix, so lives with different
    /// nonces create graphs with different ids; never zero).
    pub fn from_nonce(nonce: u64) -> GraphId {
        // splitmix64's finaliser: a bijection of u64 that spreads nearby nonces (simulations use small ones).
        let mut z = nonce.wrapping_add(0x9E37_79B9_7F4A_7C15);
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^= z >> 31;
        GraphId(if z == 0 { 1 } else { z })
    }
}

impl fmt::Display for GraphId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{:016x}", self.0)
    }
}

impl FromStr for GraphId {
    type Err = GraphIdError;

    fn from_str(text: &str) -> Result<GraphId, GraphIdError> {
        let digits = text.trim();
        if digits.is_empty() || digits.len() > 16 || !digits.bytes().all(|b| b.is_ascii_hexdigit()) {
            return Err(GraphIdError::NotHex(text.to_string()));
        }
        let value = u64::from_str_radix(digits, 16).map_err(|_| GraphIdError::NotHex(text.to_string()))?;
        GraphId::new(value).ok_or(GraphIdError::Zero)
    }
}

impl serde::Serialize for GraphId {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        serializer.collect_str(self)
    }
}

impl<'de> serde::Deserialize<'de> for GraphId {
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<GraphId, D::Error> {
        let text = String::deserialize(deserializer)?;
        text.parse().map_err(serde::de::Error::custom)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_graph_id_round_trips_through_its_text_and_refuses_zero_and_non_hex() {
        let id = GraphId::from_nonce(7);
        assert_eq!(id.to_string().len(), 16);
        assert_eq!(id.to_string().parse::<GraphId>(), Ok(id));
        assert_eq!("a1".parse::<GraphId>().map(GraphId::get), Ok(0xa1));
        assert_eq!("0".parse::<GraphId>(), Err(GraphIdError::Zero));
        assert!(matches!("lab-a".parse::<GraphId>(), Err(GraphIdError::NotHex(_))));
        assert!(matches!("11112222333344445".parse::<GraphId>(), Err(GraphIdError::NotHex(_))));
        assert_ne!(GraphId::from_nonce(1), GraphId::from_nonce(2));
        assert_ne!(GraphId::from_nonce(u64::MAX).get(), 0);
    }
}
