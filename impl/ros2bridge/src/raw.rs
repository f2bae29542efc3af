//! A ROS 2 sample as raw CDR bytes for `rustdds`: [`RawCdr`] holds the whole payload, the 4-byte encapsulation header
//! included, so that the bytes from the network go straight into `replay`'s decoders (one decoder set for logs and
//! live topics) and the bytes of [`crate::encode`] go straight onto the wire.
//!
//! `rustdds` writes the encapsulation header itself (from [`SerializerAdapter::output_encoding`]) and hands a
//! reader the bytes after it with the representation it named; this adapter takes the header off when writing and
//! puts it back when reading. Only plain CDR (XCDR1, both byte orders) is accepted, as ROS 2 sends it; a sample in
//! another representation is refused by `rustdds` and counted by the bridge.

use bytes::Bytes;
use rustdds::RepresentationIdentifier;
use rustdds::no_key::{DataWriter, Decode, DefaultDecoder, DeserializerAdapter, SerializerAdapter, SimpleDataReader};

use crate::encode::CDR_LE_HEADER;

/// A sample's CDR payload with its encapsulation header.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct RawCdr(pub Bytes);

/// Why a payload cannot be written or read as [`RawCdr`].
#[derive(Debug, thiserror::Error)]
pub enum RawCdrError {
    /// A payload to write without a little-endian plain CDR header.
    #[error("payload of {0} bytes does not start with the little-endian CDR encapsulation header")]
    NotCdrLe(usize),
}

/// The `rustdds` adapter of [`RawCdr`].
#[derive(Debug)]
pub struct RawCdrAdapter;

/// The default decoder of [`RawCdrAdapter`].
#[derive(Clone, Copy, Debug)]
pub struct RawCdrDecoder;

impl SerializerAdapter<RawCdr> for RawCdrAdapter {
    type Error = RawCdrError;

    fn output_encoding() -> RepresentationIdentifier {
        RepresentationIdentifier::CDR_LE
    }

    fn to_bytes(value: &RawCdr) -> Result<Bytes, RawCdrError> {
        if value.0.get(..2) != Some(&CDR_LE_HEADER[..2]) || value.0.len() < CDR_LE_HEADER.len() {
            return Err(RawCdrError::NotCdrLe(value.0.len()));
        }
        Ok(value.0.slice(CDR_LE_HEADER.len()..))
    }
}

const ENCODINGS: [RepresentationIdentifier; 2] = [RepresentationIdentifier::CDR_LE, RepresentationIdentifier::CDR_BE];

impl DeserializerAdapter<RawCdr> for RawCdrAdapter {
    type Error = RawCdrError;
    type Decoded = RawCdr;

    fn supported_encodings() -> &'static [RepresentationIdentifier] {
        &ENCODINGS
    }

    fn transform_decoded(decoded: RawCdr) -> RawCdr {
        decoded
    }
}

impl DefaultDecoder<RawCdr> for RawCdrAdapter {
    type Decoder = RawCdrDecoder;
    const DECODER: RawCdrDecoder = RawCdrDecoder;
}

impl<'de> Decode<'de, RawCdr> for RawCdrDecoder {
    type Error = RawCdrError;

    fn decode_bytes(self, input: &'de [u8], encoding: RepresentationIdentifier) -> Result<RawCdr, RawCdrError> {
        let mut out = Vec::with_capacity(input.len() + 4);
        out.extend_from_slice(&encoding.to_bytes());
        out.extend_from_slice(&[0, 0]);
        out.extend_from_slice(input);
        Ok(RawCdr(Bytes::from(out)))
    }
}

/// A writer of raw CDR samples.
pub type RawWriter = DataWriter<RawCdr, RawCdrAdapter>;
/// A reader of raw CDR samples.
pub type RawReader = SimpleDataReader<RawCdr, RawCdrAdapter>;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_header_comes_off_on_writing_and_back_on_reading() {
        let sample = RawCdr(Bytes::from_static(&[0, 1, 0, 0, 9, 8, 7]));
        let body = RawCdrAdapter::to_bytes(&sample).unwrap();
        assert_eq!(&body[..], &[9, 8, 7]);
        let back = RawCdrDecoder.decode_bytes(&body, RepresentationIdentifier::CDR_LE).unwrap();
        assert_eq!(back, sample);
        let big = RawCdrDecoder.decode_bytes(&[1], RepresentationIdentifier::CDR_BE).unwrap();
        assert_eq!(&big.0[..], &[0, 0, 0, 0, 1]);
    }

    #[test]
    fn a_payload_without_the_cdr_header_is_not_written() {
        assert!(RawCdrAdapter::to_bytes(&RawCdr(Bytes::from_static(&[0, 7, 0, 0, 1]))).is_err());
        assert!(RawCdrAdapter::to_bytes(&RawCdr(Bytes::from_static(&[0, 1]))).is_err());
    }
}
