//! [`Pieces`]: an encoded delta that refers to its large values instead of holding copies of them.

/// An encoded delta in pieces ([`super::Delta::encode_pieces`]): the encoding's own bytes, and the delta's large
/// values (byte values, numeric vectors) left in the delta and referred to, each at the position where its bytes
/// belong. The pieces in order ([`Pieces::iter`]), concatenated, are the encoding.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Pieces<'a> {
    own: Vec<u8>,
    /// `(position in own, bytes)`, in order of position.
    shared: Vec<(usize, &'a [u8])>,
}

impl<'a> Pieces<'a> {
    /// A value this large or larger is referred to rather than copied in: below it, the extra piece costs more than
    /// the copy it saves.
    pub const MIN_SHARED_BYTES: usize = 4096;

    pub(super) fn new(own: Vec<u8>, shared: Vec<(usize, &'a [u8])>) -> Self {
        debug_assert!(shared.windows(2).all(|w| w[0].0 <= w[1].0) && shared.iter().all(|(at, _)| *at <= own.len()));
        Pieces { own, shared }
    }

    /// The length of the whole encoding.
    pub fn len(&self) -> usize {
        self.own.len() + self.shared.iter().map(|(_, bytes)| bytes.len()).sum::<usize>()
    }

    /// Whether the encoding is empty (it never is: a delta has a header byte).
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The pieces in order; empty ones are skipped.
    pub fn iter(&self) -> impl Iterator<Item = &[u8]> + '_ {
        let mut from = 0;
        let between = self.shared.iter().flat_map(move |&(at, bytes)| {
            let own = &self.own[from..at];
            from = at;
            [own, bytes]
        });
        let last_at = self.shared.last().map_or(0, |(at, _)| *at);
        between.chain(std::iter::once(&self.own[last_at..])).filter(|piece| !piece.is_empty())
    }

    /// The encoding in one buffer (one copy of every piece).
    pub fn to_vec(&self) -> Vec<u8> {
        let mut out = Vec::with_capacity(self.len());
        for piece in self.iter() {
            out.extend_from_slice(piece);
        }
        out
    }
}
