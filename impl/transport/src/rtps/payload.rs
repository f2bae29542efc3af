//! A sample on the wire: opaque bytes as a CDR `sequence<octet>` ([`Payload`], [`OctetsAdapter`]), and the
//! estimate of the wire bytes a sample costs ([`estimated_wire_bytes`]).

use bytes::Bytes;
use rustdds::RepresentationIdentifier;
use rustdds::no_key::{DataWriter, Decode, DefaultDecoder, DeserializerAdapter, SerializerAdapter, SimpleDataReader};

/// Estimated wire bytes of one sample of `payload` bytes, written reliably (with its heartbeat) or best-effort
/// (see the module documentation).
pub fn estimated_wire_bytes(payload: usize, reliable: bool) -> usize {
    let datagrams = payload.div_ceil(64 << 10).max(1);
    let heartbeat = if reliable { 32 } else { 0 };
    (payload + 8).next_multiple_of(4) + 24 + heartbeat + 48 * datagrams
}

/// A sample as `rustdds` sees it: opaque bytes.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Payload(pub Bytes);

/// Why bytes from the network are not a CDR `sequence<octet>`.
#[derive(Debug, thiserror::Error)]
pub enum PayloadError {
    /// Fewer than 4 bytes, or a length past the end.
    #[error("sample of {got} bytes is not a cdr octet sequence (declared length {declared:?})")]
    Truncated {
        /// Bytes present.
        got: usize,
        /// The length field, if there was one.
        declared: Option<u32>,
    },
}

/// Serializes and deserializes [`Payload`] as a CDR `sequence<octet>` without going through serde per byte.
#[derive(Debug)]
pub struct OctetsAdapter;

/// The default decoder of [`OctetsAdapter`].
#[derive(Clone, Copy, Debug)]
pub struct OctetsDecoder;

impl SerializerAdapter<Payload> for OctetsAdapter {
    type Error = PayloadError;

    fn output_encoding() -> RepresentationIdentifier {
        RepresentationIdentifier::CDR_LE
    }

    fn to_bytes(value: &Payload) -> Result<Bytes, PayloadError> {
        let len = u32::try_from(value.0.len()).map_err(|_| PayloadError::Truncated { got: 0, declared: None })?;
        let mut out = Vec::with_capacity(4 + value.0.len());
        out.extend_from_slice(&len.to_le_bytes());
        out.extend_from_slice(&value.0);
        Ok(Bytes::from(out))
    }
}

const ENCODINGS: [RepresentationIdentifier; 2] = [RepresentationIdentifier::CDR_LE, RepresentationIdentifier::CDR_BE];

impl DeserializerAdapter<Payload> for OctetsAdapter {
    type Error = PayloadError;
    type Decoded = Payload;

    fn supported_encodings() -> &'static [RepresentationIdentifier] {
        &ENCODINGS
    }

    fn transform_decoded(decoded: Payload) -> Payload {
        decoded
    }
}

impl DefaultDecoder<Payload> for OctetsAdapter {
    type Decoder = OctetsDecoder;
    const DECODER: OctetsDecoder = OctetsDecoder;
}

impl<'de> Decode<'de, Payload> for OctetsDecoder {
    type Error = PayloadError;

    fn decode_bytes(self, input: &'de [u8], encoding: RepresentationIdentifier) -> Result<Payload, PayloadError> {
        let Some(head) = input.get(..4) else {
            return Err(PayloadError::Truncated { got: input.len(), declared: None });
        };
        let head = [head[0], head[1], head[2], head[3]];
        let len = if encoding == RepresentationIdentifier::CDR_BE {
            u32::from_be_bytes(head)
        } else {
            u32::from_le_bytes(head)
        };
        let body = input
            .get(4..)
            .and_then(|rest| rest.get(..len as usize))
            .ok_or(PayloadError::Truncated { got: input.len(), declared: Some(len) })?;
        Ok(Payload(Bytes::copy_from_slice(body)))
    }
}

pub(super) type Writer = DataWriter<Payload, OctetsAdapter>;
pub(super) type Reader = SimpleDataReader<Payload, OctetsAdapter>;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn octets_round_trip_and_truncation_is_an_error() {
        let payload = Payload(Bytes::from_static(b"hello"));
        let bytes = OctetsAdapter::to_bytes(&payload).unwrap();
        assert_eq!(&bytes[..4], &5u32.to_le_bytes());
        let back = OctetsDecoder.decode_bytes(&bytes, RepresentationIdentifier::CDR_LE).unwrap();
        assert_eq!(back, payload);
        for cut in 0..bytes.len() {
            assert!(OctetsDecoder.decode_bytes(&bytes[..cut], RepresentationIdentifier::CDR_LE).is_err(), "cut {cut}");
        }
        let be = [0, 0, 0, 2, 7, 8];
        assert_eq!(&OctetsDecoder.decode_bytes(&be, RepresentationIdentifier::CDR_BE).unwrap().0[..], &[7, 8]);
    }

    #[test]
    fn wire_estimate_grows_with_datagrams() {
        // A 50-byte envelope: IPv4 + UDP + RTPS header (48), DATA (24), encapsulation and length (8), padding to 4
        // (2); reliable adds the heartbeat (32). Measured on loopback: 132 and 164 bytes per datagram.
        assert_eq!(estimated_wire_bytes(50, false), 132);
        assert_eq!(estimated_wire_bytes(50, true), 164);
        assert!(estimated_wire_bytes(1 << 20, true) > (1 << 20) + 16 * 48);
    }
}
