//! Who is on this host: the peers a [`super::HybridTransport`] has heard through shared memory, from their
//! [`Hello`]s. Hearing a peer's hello through a shared-memory lane is the proof that it shares this host (and this
//! network namespace, which the lanes' names include): no host key to compare, nothing to trust but the lane itself.
//!
//! Pure bookkeeping, timed by the `now_ns` its callers pass: the transport's thread feeds it hellos and the time.

use crate::EndpointId;

/// First 8 bytes of a hello on the shared-memory `Sync` lane (28 bytes follow: the sender's RTPS writer endpoint
/// and its readers' GUID prefix). Hellos are consumed by the hybrid transport and never reach an agent.
pub const HELLO: [u8; 8] = *b"\xffSHMhi01";

/// How often a hybrid transport says hello on its lanes.
pub const HELLO_PERIOD_NS: u64 = 500_000_000;

/// A peer not heard for this long is no longer taken to share the host: samples for it go by RTPS as well (harmless
/// if it is still there; a stopped or killed process says nothing).
pub const PEER_EXPIRY_NS: u64 = 3_000_000_000;

/// Most same-host peers remembered (a lane has far fewer ends, `ShmSettings::max_endpoints`).
const MAX_PEERS: usize = 256;

/// What a hybrid transport tells the other ends of its lanes: who it is on RTPS.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Hello {
    /// Its RTPS endpoint id (its publishing participant's GUID prefix): the origin of its RTPS samples.
    pub writer: EndpointId,
    /// The GUID prefix of the participant holding its RTPS readers: how this host's writers recognise them among
    /// their matched readers.
    pub readers: [u8; 12],
}

impl Hello {
    /// Its bytes: [`HELLO`], the writer endpoint (16 bytes, little-endian), the readers' prefix (12 bytes).
    pub fn encode(&self) -> Vec<u8> {
        let mut bytes = HELLO.to_vec();
        bytes.extend_from_slice(&self.writer.0.to_le_bytes());
        bytes.extend_from_slice(&self.readers);
        bytes
    }

    /// The hello in `bytes`; `None` if they are not one (any other sample).
    pub fn decode(bytes: &[u8]) -> Option<Hello> {
        let rest = bytes.strip_prefix(&HELLO)?;
        if rest.len() != 28 {
            return None;
        }
        let writer = EndpointId(u128::from_le_bytes(rest[..16].try_into().ok()?));
        let readers = rest[16..].try_into().ok()?;
        Some(Hello { writer, readers })
    }
}

/// One same-host peer: its lane endpoint, what it said last, and when.
#[derive(Clone, Copy, Debug)]
struct Peer {
    lane: EndpointId,
    hello: Hello,
    heard_ns: u64,
}

/// The same-host peers heard lately.
#[derive(Debug, Default)]
pub struct Peers {
    list: Vec<Peer>,
    /// Peers newly heard since the start (a peer heard again after expiring counts again).
    learned: u64,
}

impl Peers {
    /// Records `hello`, heard at `now_ns` from the lane endpoint `lane`; `true` when the peer is new.
    pub fn heard(&mut self, lane: EndpointId, hello: Hello, now_ns: u64) -> bool {
        if let Some(peer) = self.list.iter_mut().find(|p| p.lane == lane) {
            peer.hello = hello;
            peer.heard_ns = now_ns;
            return false;
        }
        if self.list.len() >= MAX_PEERS {
            return false;
        }
        self.list.push(Peer { lane, hello, heard_ns: now_ns });
        self.learned += 1;
        true
    }

    /// Forgets the peers not heard for [`PEER_EXPIRY_NS`] before `now_ns`.
    pub fn expire(&mut self, now_ns: u64) {
        self.list.retain(|p| now_ns.saturating_sub(p.heard_ns) <= PEER_EXPIRY_NS);
    }

    /// Whether the RTPS reader of GUID prefix `prefix` belongs to a same-host peer.
    pub fn has_reader(&self, prefix: &[u8; 12]) -> bool {
        self.list.iter().any(|p| &p.hello.readers == prefix)
    }

    /// Whether `endpoint` is a same-host peer, by its RTPS endpoint id or its lane endpoint.
    pub fn has_endpoint(&self, endpoint: EndpointId) -> bool {
        self.list.iter().any(|p| p.hello.writer == endpoint || p.lane == endpoint)
    }

    /// The RTPS endpoint id of the peer at lane endpoint `lane`, if it has said hello.
    pub fn writer_of(&self, lane: EndpointId) -> Option<EndpointId> {
        self.list.iter().find(|p| p.lane == lane).map(|p| p.hello.writer)
    }

    /// How many peers are remembered now.
    pub fn len(&self) -> usize {
        self.list.len()
    }

    /// Whether no peer is remembered.
    pub fn is_empty(&self) -> bool {
        self.list.is_empty()
    }

    /// Peers newly heard since the start.
    pub fn learned(&self) -> u64 {
        self.learned
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn hello(writer: u128, reader: u8) -> Hello {
        Hello { writer: EndpointId(writer), readers: [reader; 12] }
    }

    #[test]
    fn a_hello_survives_its_encoding_and_nothing_else_decodes_as_one() {
        let h = hello(0x0102_0304_0506_0708_090a_0b0c, 9);
        assert_eq!(Hello::decode(&h.encode()), Some(h));
        assert_eq!(Hello::decode(b"\xffSHMhi01short"), None);
        assert_eq!(Hello::decode(&h.encode()[1..]), None);
        let mut long = h.encode();
        long.push(0);
        assert_eq!(Hello::decode(&long), None);
    }

    #[test]
    fn a_peer_is_same_host_by_its_readers_and_endpoints_until_it_falls_silent() {
        let mut peers = Peers::default();
        assert!(peers.heard(EndpointId(1 << 100), hello(7, 3), 0));
        assert!(!peers.heard(EndpointId(1 << 100), hello(8, 4), HELLO_PERIOD_NS), "the same lane again");
        assert!(peers.has_reader(&[4; 12]) && !peers.has_reader(&[3; 12]), "the latest hello counts");
        assert!(peers.has_endpoint(EndpointId(8)) && peers.has_endpoint(EndpointId(1 << 100)));
        assert_eq!(peers.writer_of(EndpointId(1 << 100)), Some(EndpointId(8)));
        peers.expire(HELLO_PERIOD_NS + PEER_EXPIRY_NS);
        assert_eq!(peers.len(), 1);
        peers.expire(HELLO_PERIOD_NS + PEER_EXPIRY_NS + 1);
        assert!(peers.is_empty() && !peers.has_endpoint(EndpointId(8)));
        assert!(peers.heard(EndpointId(1 << 100), hello(8, 4), 10 * PEER_EXPIRY_NS));
        assert_eq!(peers.learned(), 2);
    }
}
