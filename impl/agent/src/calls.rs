//! Remote calls between agents: request/reply on the `Calls` channel, beside the graph protocol.
//!
//! **Caller.** [`crate::Agent::call`] encodes a typed request with `postcard`, sends a
//! [`Message::CallRequest`] with a fresh call id to one agent and waits up to
//! a timeout for the [`Message::CallReply`] with the same id. At most
//! [`AgentConfig::max_calls_in_flight`](crate::AgentConfig::max_calls_in_flight) calls wait at once; a reply that
//! comes after its caller gave up is dropped and counted.
//!
//! **Server.** An agent serves calls only after [`crate::Agent::serve_calls`] gave it a [`CallServer`] (typically a
//! BICA runtime's [`bica::service::Service`]). The receiving thread hands each request addressed to this agent to
//! the server with a [`CallReplier`] and goes on; the server answers later from any thread (for a BICA runtime:
//! the scheduler thread, between steps), and the replier only puts the reply into a bounded outbox that the
//! agent's own thread publishes, so **the server never does network I/O and never blocks**. An agent without a
//! server answers [`CallFault::NoRuntime`].

use std::collections::HashMap;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use bytes::Bytes;
use crossbeam_channel::{Receiver, Sender, TrySendError, bounded};

use crate::AgentId;
use crate::envelope::{CallFault, Message};

/// Why a call gave no response. Messages say which agent, which method and what happened.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum CallError {
    /// The serving agent has no such method.
    #[error("call `{method}` to {to}: {detail}")]
    UnknownMethod {
        /// The serving agent.
        to: AgentId,
        /// The method.
        method: String,
        /// What the server said.
        detail: String,
    },
    /// The server could not decode the request bytes.
    #[error("call `{method}` to {to}: bad request: {detail}")]
    BadRequest {
        /// The serving agent.
        to: AgentId,
        /// The method.
        method: String,
        /// What the server's decoder said.
        detail: String,
    },
    /// The method ran and failed.
    #[error("call `{method}` to {to}: {detail}")]
    Failed {
        /// The serving agent.
        to: AgentId,
        /// The method.
        method: String,
        /// Why.
        detail: String,
    },
    /// The server was too busy or has stopped; nothing ran.
    #[error("call `{method}` to {to}: server busy: {detail}")]
    Busy {
        /// The serving agent.
        to: AgentId,
        /// The method.
        method: String,
        /// Why.
        detail: String,
    },
    /// The serving agent has no BICA runtime attached.
    #[error("call `{method}` to {to}: no runtime: {detail}")]
    NoRuntime {
        /// The serving agent.
        to: AgentId,
        /// The method.
        method: String,
        /// What the agent said.
        detail: String,
    },
    /// No reply within the timeout (the agent may not exist, be unreachable or be slow).
    #[error("call `{method}` to {to}: no reply within {after:?}")]
    Timeout {
        /// The agent called.
        to: AgentId,
        /// The method.
        method: String,
        /// The timeout.
        after: Duration,
    },
    /// Too many calls already wait for replies.
    #[error("call `{method}` to {to}: {limit} calls already in flight")]
    TooManyInFlight {
        /// The agent called.
        to: AgentId,
        /// The method.
        method: String,
        /// The limit.
        limit: usize,
    },
    /// The request could not be encoded, or the response bytes are not the expected type.
    #[error("call `{method}` to {to}: {detail}")]
    Codec {
        /// The agent called.
        to: AgentId,
        /// The method.
        method: String,
        /// What the codec said.
        detail: String,
    },
    /// The request could not be published.
    #[error("call `{method}` to {to}: sending the request failed: {detail}")]
    Send {
        /// The agent called.
        to: AgentId,
        /// The method.
        method: String,
        /// The transport's error.
        detail: String,
    },
}

impl CallError {
    fn of_fault(to: AgentId, method: &str, fault: CallFault) -> Self {
        let method = method.to_owned();
        match fault {
            CallFault::UnknownMethod(detail) => CallError::UnknownMethod { to, method, detail },
            CallFault::BadRequest(detail) => CallError::BadRequest { to, method, detail },
            CallFault::Failed(detail) => CallError::Failed { to, method, detail },
            CallFault::Busy(detail) => CallError::Busy { to, method, detail },
            CallFault::NoRuntime(detail) => CallError::NoRuntime { to, method, detail },
        }
    }
}

/// What serves the calls addressed to an agent.
pub trait CallServer: Send + Sync + 'static {
    /// Starts serving `method` with the request bytes `args`; must not block. The reply goes through `reply`,
    /// now or later, from any thread.
    fn serve(&self, method: &str, args: Bytes, reply: CallReplier);
}

/// A BICA runtime's named methods, served between its steps.
impl CallServer for bica::service::Service {
    fn serve(&self, method: &str, args: Bytes, reply: CallReplier) {
        use bica::service::ServiceError;
        self.dispatch(method, args, move |result| {
            reply.send(result.map(Bytes::from).map_err(|error| {
                let detail = error.to_string();
                match error {
                    ServiceError::UnknownMethod { .. } => CallFault::UnknownMethod(detail),
                    ServiceError::BadRequest { .. } => CallFault::BadRequest(detail),
                    ServiceError::Failed { .. } => CallFault::Failed(detail),
                    ServiceError::Busy { .. } | ServiceError::Stopped { .. } => CallFault::Busy(detail),
                }
            }));
        });
    }
}

/// The way back for one call's reply: puts it into the serving agent's bounded outbox (never blocks; a full
/// outbox drops the reply and counts it, and the caller times out).
#[derive(Debug)]
pub struct CallReplier {
    pub(crate) me: AgentId,
    pub(crate) to: AgentId,
    pub(crate) call: u64,
    pub(crate) outbox: Sender<Message>,
    pub(crate) dropped: Arc<AtomicU64>,
}

impl CallReplier {
    /// Sends the response bytes, or the fault.
    pub fn send(self, result: Result<Bytes, CallFault>) {
        let message = Message::CallReply { from: self.me, to: self.to, call: self.call, result };
        match self.outbox.try_send(message) {
            Ok(()) => {}
            Err(TrySendError::Full(_)) => {
                self.dropped.fetch_add(1, Ordering::Relaxed);
                tracing::warn!(
                    "{}: reply outbox full; dropped the reply to call {} of {}",
                    self.me,
                    self.call,
                    self.to
                );
            }
            // The agent is shutting down.
            Err(TrySendError::Disconnected(_)) => {
                self.dropped.fetch_add(1, Ordering::Relaxed);
            }
        }
    }
}

type Slot = Sender<Result<Bytes, CallFault>>;

/// The caller's side: calls waiting for replies, by id.
#[derive(Debug)]
pub(crate) struct CallTable {
    pending: Mutex<HashMap<u64, (AgentId, Slot)>>,
    next: AtomicU64,
    limit: usize,
    pub(crate) late: AtomicU64,
}

impl CallTable {
    pub(crate) fn new(limit: usize, first_id: u64) -> Self {
        CallTable {
            pending: Mutex::new(HashMap::new()),
            next: AtomicU64::new(first_id),
            limit: limit.max(1),
            late: AtomicU64::new(0),
        }
    }

    /// Reserves a call id for a call to `to`, or refuses when the table is full.
    pub(crate) fn open(
        self: &Arc<Self>,
        to: AgentId,
        method: &str,
    ) -> Result<(u64, Receiver<Result<Bytes, CallFault>>), CallError> {
        let mut pending = self.pending.lock().unwrap_or_else(|p| p.into_inner());
        if pending.len() >= self.limit {
            return Err(CallError::TooManyInFlight { to, method: method.to_owned(), limit: self.limit });
        }
        let call = self.next.fetch_add(1, Ordering::Relaxed);
        let (sender, receiver) = bounded(1);
        pending.insert(call, (to, sender));
        Ok((call, receiver))
    }

    pub(crate) fn close(&self, call: u64) {
        self.pending.lock().unwrap_or_else(|p| p.into_inner()).remove(&call);
    }

    /// Routes a reply from `from`; a reply nobody waits for (late, or from another agent) is counted.
    pub(crate) fn deliver(&self, from: AgentId, call: u64, result: Result<Bytes, CallFault>) {
        let slot = {
            let mut pending = self.pending.lock().unwrap_or_else(|p| p.into_inner());
            match pending.get(&call) {
                Some((to, _)) if *to == from => pending.remove(&call).map(|(_, slot)| slot),
                _ => None,
            }
        };
        match slot {
            Some(slot) => {
                let _ = slot.try_send(result);
            }
            None => {
                self.late.fetch_add(1, Ordering::Relaxed);
                tracing::debug!("a reply to call {call} from {from} came after its caller gave up");
            }
        }
    }

    pub(crate) fn in_flight(&self) -> usize {
        self.pending.lock().unwrap_or_else(|p| p.into_inner()).len()
    }
}

/// A call sent and not answered yet. Dropping it gives the call up (a later reply is dropped and counted).
#[derive(Debug)]
pub struct PendingCall {
    pub(crate) table: Arc<CallTable>,
    pub(crate) call: u64,
    pub(crate) to: AgentId,
    pub(crate) method: String,
    pub(crate) receiver: Receiver<Result<Bytes, CallFault>>,
}

impl PendingCall {
    /// The call id (echoed in the reply).
    pub fn id(&self) -> u64 {
        self.call
    }

    /// Waits up to `timeout` for the response bytes.
    ///
    /// # Errors
    /// [`CallError::Timeout`], or the server's fault.
    pub fn wait(self, timeout: Duration) -> Result<Bytes, CallError> {
        match self.receiver.recv_timeout(timeout) {
            Ok(result) => result.map_err(|fault| CallError::of_fault(self.to, &self.method, fault)),
            Err(_) => Err(CallError::Timeout { to: self.to, method: self.method.clone(), after: timeout }),
        }
    }

    /// The reply, if it has arrived (for callers that pump agents by hand).
    pub fn try_take(&self) -> Option<Result<Bytes, CallError>> {
        self.receiver
            .try_recv()
            .ok()
            .map(|result| result.map_err(|fault| CallError::of_fault(self.to, &self.method, fault)))
    }

    /// Decodes response bytes of this call as `R`.
    ///
    /// # Errors
    /// [`CallError::Codec`] when they are not an `R`.
    pub fn decode<R: serde::de::DeserializeOwned>(&self, bytes: &[u8]) -> Result<R, CallError> {
        decode_response(self.to, &self.method, bytes)
    }
}

impl Drop for PendingCall {
    fn drop(&mut self) {
        self.table.close(self.call);
    }
}

/// Decodes the response bytes of `method` from `to` as `R` (all bytes must be used).
pub(crate) fn decode_response<R: serde::de::DeserializeOwned>(
    to: AgentId,
    method: &str,
    bytes: &[u8],
) -> Result<R, CallError> {
    let codec = |detail: String| CallError::Codec { to, method: method.to_owned(), detail };
    match postcard::take_from_bytes::<R>(bytes) {
        Ok((response, [])) => Ok(response),
        Ok((_, rest)) => Err(codec(format!("{} trailing bytes after the response", rest.len()))),
        Err(e) => Err(codec(format!("the response ({} bytes) does not decode: {e}", bytes.len()))),
    }
}

/// The server's side: the attached server and the outbox of replies.
pub(crate) struct CallService {
    pub(crate) server: Mutex<Option<Arc<dyn CallServer>>>,
    pub(crate) outbox: Sender<Message>,
    pub(crate) outbox_rx: Receiver<Message>,
    pub(crate) dropped: Arc<AtomicU64>,
    pub(crate) served: AtomicU64,
}

impl CallService {
    pub(crate) fn new(capacity: usize) -> Self {
        let (outbox, outbox_rx) = bounded(capacity.max(1));
        CallService {
            server: Mutex::new(None),
            outbox,
            outbox_rx,
            dropped: Arc::new(AtomicU64::new(0)),
            served: AtomicU64::new(0),
        }
    }

    /// Hands a request to the server, or answers that there is none.
    pub(crate) fn request(&self, me: AgentId, from: AgentId, call: u64, method: &str, args: Bytes) {
        let replier =
            CallReplier { me, to: from, call, outbox: self.outbox.clone(), dropped: Arc::clone(&self.dropped) };
        let server = self.server.lock().unwrap_or_else(|p| p.into_inner()).clone();
        self.served.fetch_add(1, Ordering::Relaxed);
        match server {
            Some(server) => server.serve(method, args, replier),
            None => replier.send(Err(CallFault::NoRuntime(format!("{me} serves no remote calls")))),
        }
    }
}
