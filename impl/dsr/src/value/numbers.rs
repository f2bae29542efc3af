//! [`Numbers`]: the shared, immutable buffer of a numeric vector value (`vec<f32>`, `vec<u64>`), either owned or a
//! view into a received sample's buffer.
//!
//! **When a vector is a view (no copy).** Decoding from a shared buffer ([`crate::Delta::decode_shared`]) keeps a
//! vector as a view of that buffer when all of these hold; otherwise it is copied once into an owned buffer:
//! - this host is little-endian (the wire form is little-endian values);
//! - the vector's bytes start at an address aligned for its element (4 bytes for `f32`, 8 for `u64`) and their
//!   length is a whole number of elements. An encoder places a vector of 4 KiB or more at a multiple of its
//!   element's size from the start of its buffer ([`crate::Delta`]'s wire format), so it lands aligned when the
//!   received buffer starts 8-aligned (heap buffers, shared-memory chunks) and the delta sits where it was encoded
//!   in it; a delta re-wrapped in another message (a repair list) may not. Decoders check, never assume;
//! - it is worth sharing: at least 4 KiB and at least an eighth of the buffer (a point cloud's four columns in one
//!   delta are shared; the many small vectors of a snapshot are copied, so one of them kept for long never holds the
//!   whole snapshot's buffer alive).

use std::fmt;
use std::ops::Deref;
use std::sync::Arc;

use bytemuck::Pod;
use bytes::Bytes;

/// The buffer of a numeric vector value: owned, or a view of little-endian bytes received (see the module
/// documentation). Clones share the buffer; reads see a `&[T]` either way.
#[derive(Clone)]
pub struct Numbers<T>(Repr<T>);

#[derive(Clone)]
enum Repr<T> {
    Owned(Arc<[T]>),
    /// Invariant: aligned for `T`, a whole number of `T`, on a little-endian host ([`Numbers::view`]).
    View(Bytes),
}

impl<T: Pod> Numbers<T> {
    /// A view of `bytes` (little-endian values) with no copy, when this host is little-endian and `bytes` are
    /// aligned for `T` and a whole number of them; `None` otherwise.
    pub fn view(bytes: Bytes) -> Option<Self> {
        let fits = cfg!(target_endian = "little") && bytemuck::try_cast_slice::<u8, T>(&bytes).is_ok();
        fits.then_some(Numbers(Repr::View(bytes)))
    }

    /// Whether this is a view of a received buffer rather than an owned copy.
    pub fn is_view(&self) -> bool {
        matches!(self.0, Repr::View(_))
    }

    /// The values.
    pub fn as_slice(&self) -> &[T] {
        match &self.0 {
            Repr::Owned(values) => values,
            // The invariant of `View` makes the cast succeed; an empty slice would only hide a broken invariant.
            Repr::View(bytes) => bytemuck::try_cast_slice(bytes).unwrap_or_default(),
        }
    }
}

impl<T: Pod> Deref for Numbers<T> {
    type Target = [T];
    fn deref(&self) -> &[T] {
        self.as_slice()
    }
}

impl<T: Pod> AsRef<[T]> for Numbers<T> {
    fn as_ref(&self) -> &[T] {
        self.as_slice()
    }
}

impl<T> From<Arc<[T]>> for Numbers<T> {
    fn from(values: Arc<[T]>) -> Self {
        Numbers(Repr::Owned(values))
    }
}

impl<T> From<Vec<T>> for Numbers<T> {
    fn from(values: Vec<T>) -> Self {
        Numbers(Repr::Owned(values.into()))
    }
}

impl<T: Clone> From<&[T]> for Numbers<T> {
    fn from(values: &[T]) -> Self {
        Numbers(Repr::Owned(values.into()))
    }
}

impl<T: Clone, const N: usize> From<[T; N]> for Numbers<T> {
    fn from(values: [T; N]) -> Self {
        Numbers(Repr::Owned(Arc::from(values.as_slice())))
    }
}

impl<T> FromIterator<T> for Numbers<T> {
    fn from_iter<I: IntoIterator<Item = T>>(iter: I) -> Self {
        Numbers(Repr::Owned(iter.into_iter().collect()))
    }
}

impl<T: Pod + PartialEq> PartialEq for Numbers<T> {
    fn eq(&self, other: &Self) -> bool {
        self.as_slice() == other.as_slice()
    }
}

impl<T: Pod + std::hash::Hash> std::hash::Hash for Numbers<T> {
    fn hash<H: std::hash::Hasher>(&self, state: &mut H) {
        self.as_slice().hash(state);
    }
}

impl<T: Pod + fmt::Debug> fmt::Debug for Numbers<T> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        self.as_slice().fmt(f)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_aligned_whole_buffer_is_a_view_and_reads_the_little_endian_values() {
        let values: Vec<f32> = vec![1.5, -2.0, 3.25];
        let bytes = Bytes::from(values.iter().flat_map(|v| v.to_le_bytes()).collect::<Vec<u8>>());
        let view = Numbers::<f32>::view(bytes).expect("a Vec<u8>'s buffer is aligned for f32 on this allocator");
        assert!(view.is_view());
        assert_eq!(&*view, values.as_slice());
        let owned = Numbers::from(values.clone());
        assert!(!owned.is_view());
        assert_eq!(owned.as_slice(), values.as_slice());
    }

    #[test]
    fn a_misaligned_or_ragged_buffer_is_no_view() {
        let bytes = Bytes::from(vec![0u8; 4 * 9 + 1]);
        assert!(Numbers::<f32>::view(bytes.slice(1..)).is_none(), "misaligned by one byte");
        assert!(Numbers::<f32>::view(bytes.slice(0..7)).is_none(), "not a whole number of f32");
        assert!(Numbers::<u64>::view(bytes.slice(4..20)).is_none(), "aligned for f32, not for u64");
    }
}
