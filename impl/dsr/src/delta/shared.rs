//! [`LargeValues`]: how many of a decoded delta's large values share the buffer it was decoded from, and how many are
//! copies, so that an agent can tell whether its frames and point clouds arrive without a copy.

use crate::value::SHARE_MIN_BYTES;

use super::Delta;

/// Large values (byte values and numeric vectors of 4 KiB or more) of decoded deltas, by whether they are read in
/// place from the received buffer ([`Delta::decode_shared`]) or were copied out of it.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct LargeValues {
    /// Values whose bytes lie in the received buffer: no copy was made.
    pub shared: u64,
    /// Values copied out of it (a vector that did not land aligned, a value too small a part of a large snapshot).
    pub copied: u64,
}

impl std::ops::AddAssign for LargeValues {
    fn add_assign(&mut self, other: LargeValues) {
        self.shared += other.shared;
        self.copied += other.copied;
    }
}

impl Delta {
    /// Counts this delta's values of 4 KiB or more by whether their bytes lie inside `buffer` (the bytes it was
    /// decoded from with [`Delta::decode_shared`]) or elsewhere (copies). Numeric vectors count on little-endian
    /// hosts only, where their bytes are their wire form; elsewhere they are always copied and not counted.
    ///
    /// # Examples
    /// ```
    /// use dsr::{Delta, LargeValues, NewNode, Replica, ReplicaId, Value};
    /// let mut writer = Replica::new(ReplicaId(1));
    /// let (camera, _) = writer.insert_node(1, NewNode::new("camera", "cam")).unwrap();
    /// let frame = Value::Bytes(bytes::Bytes::from(vec![9u8; 64 * 1024]));
    /// let sample = bytes::Bytes::from(writer.set_attrs(2, camera, [("cam_rgb", frame)]).unwrap().encode());
    /// let shared = Delta::decode_shared(&sample).unwrap();
    /// assert_eq!(shared.large_values_in(&sample), LargeValues { shared: 1, copied: 0 });
    /// let copied = Delta::decode(&sample).unwrap();
    /// assert_eq!(copied.large_values_in(&sample), LargeValues { shared: 0, copied: 1 });
    /// ```
    pub fn large_values_in(&self, buffer: &[u8]) -> LargeValues {
        let inside = buffer.as_ptr_range();
        let mut counts = LargeValues::default();
        let registers = self.store.nodes.values().flat_map(|node| node.attrs.values());
        let registers = registers.chain(self.store.edges.values().flat_map(|edge| edge.attrs.values()));
        let blocks = registers.flat_map(|register| register.values.iter()).filter_map(|entry| entry.value.wire_block());
        for block in blocks.filter(|block| block.bytes.len() >= SHARE_MIN_BYTES) {
            if inside.contains(&block.bytes.as_ptr()) {
                counts.shared += 1;
            } else {
                counts.copied += 1;
            }
        }
        counts
    }
}
