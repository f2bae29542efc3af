//! Pacing: when each message of a log is due, at the recorded timing times a rate factor or as fast as possible,
//! looping the log K times.
//!
//! With a rate factor the [`Pacer`] reads an injected [`Clock`] once, at its first message, and from then on
//! computes due times from the log: message `i` of loop `k` is due at `start + ((t_i - t_0) + k·span) / rate`, where `span` is the log's
//! duration plus one mean gap between messages (100 ms for a log of one message), so loops follow each other like
//! one longer recording. With [`Rate::Max`] every message is due at once (the clock's current reading). The pacer
//! never sleeps: the caller waits until `due_ns` (or not, in a simulation).

use crate::log::Message;

/// How fast to replay.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Rate {
    /// As fast as possible.
    Max,
    /// The recorded timing divided by this factor (2.0 plays twice as fast); must be positive and finite.
    Factor(f64),
}

impl std::str::FromStr for Rate {
    type Err = String;

    /// `max`, or a positive factor such as `1`, `0.5`, `10`.
    fn from_str(text: &str) -> Result<Self, Self::Err> {
        if text == "max" {
            return Ok(Rate::Max);
        }
        match text.parse::<f64>() {
            Ok(factor) if factor.is_finite() && factor > 0.0 => Ok(Rate::Factor(factor)),
            _ => Err(format!("rate must be `max` or a positive number, not {text:?}")),
        }
    }
}

/// A source of monotonic time in ns.
pub trait Clock {
    /// The current time, ns (monotonic; any origin).
    fn now_ns(&mut self) -> u64;
}

impl<F: FnMut() -> u64> Clock for F {
    fn now_ns(&mut self) -> u64 {
        self()
    }
}

/// A message with the time it is due.
#[derive(Debug, Clone, Copy)]
pub struct Paced<'a> {
    /// When to deliver it, on the pacer's clock.
    pub due_ns: u64,
    /// Which pass over the log (0-based).
    pub loop_index: u32,
    /// What to add to the log's times for this pass (`loop_index · span`), so stamps keep growing across loops.
    pub shift_ns: u64,
    /// The message.
    pub message: &'a Message,
}

/// Iterates a log's messages (already in log-time order) with their due times.
pub struct Pacer<'a, C> {
    messages: &'a [Message],
    rate: Rate,
    loops: u32,
    clock: C,
    start: Option<u64>,
    next: usize,
    loop_index: u32,
    span: u64,
}

impl<'a, C: Clock> Pacer<'a, C> {
    /// Paces `messages` (sorted by log time) `loops` times (0 plays nothing) at `rate` on `clock`.
    pub fn new(messages: &'a [Message], rate: Rate, loops: u32, clock: C) -> Self {
        let span = match (messages.first(), messages.last()) {
            (Some(first), Some(last)) if messages.len() > 1 => {
                let duration = last.log_time.saturating_sub(first.log_time);
                duration.saturating_add(duration / (messages.len() as u64 - 1))
            }
            _ => 100_000_000,
        };
        Pacer { messages, rate, loops, clock, start: None, next: 0, loop_index: 0, span }
    }

    /// The time one pass over the log takes on the log's clock, ns (see the module documentation).
    pub fn span_ns(&self) -> u64 {
        self.span
    }
}

impl<'a, C: Clock> Iterator for Pacer<'a, C> {
    type Item = Paced<'a>;

    fn next(&mut self) -> Option<Paced<'a>> {
        if self.next == self.messages.len() {
            self.next = 0;
            self.loop_index += 1;
        }
        if self.loop_index >= self.loops || self.messages.is_empty() {
            return None;
        }
        let message = &self.messages[self.next];
        self.next += 1;
        let shift_ns = self.span.saturating_mul(u64::from(self.loop_index));
        let due_ns = match self.rate {
            Rate::Max => self.clock.now_ns(),
            Rate::Factor(factor) => {
                let start = match self.start {
                    Some(start) => start,
                    None => *self.start.insert(self.clock.now_ns()),
                };
                let offset = message.log_time.saturating_sub(self.messages[0].log_time).saturating_add(shift_ns);
                start.saturating_add((offset as f64 / factor) as u64)
            }
        };
        Some(Paced { due_ns, loop_index: self.loop_index, shift_ns, message })
    }
}
