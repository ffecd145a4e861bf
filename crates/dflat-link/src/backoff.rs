//! Reconnect backoff for the stream transports (TCP, serial): pure.
//!
//! The first retry waits [`Backoff::MIN`], each failed attempt doubles the
//! wait up to [`Backoff::MAX`]; a successful connection resets it. No clock
//! here: the caller sleeps for what [`Backoff::next_delay`] returns.

use std::time::Duration;

/// Doubling delay between reconnect attempts.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Backoff {
    next: Duration,
    attempts: u32,
}

impl Default for Backoff {
    fn default() -> Self {
        Self::new()
    }
}

impl Backoff {
    /// First retry delay (100 ms).
    pub const MIN: Duration = Duration::from_millis(100);
    /// Largest retry delay (2 s).
    pub const MAX: Duration = Duration::from_secs(2);

    /// A fresh backoff: the next delay is [`Self::MIN`].
    pub fn new() -> Self {
        Self {
            next: Self::MIN,
            attempts: 0,
        }
    }

    /// The delay before the next attempt; doubles the one after (≤ [`Self::MAX`]).
    pub fn next_delay(&mut self) -> Duration {
        let d = self.next;
        self.next = (self.next * 2).min(Self::MAX);
        self.attempts = self.attempts.saturating_add(1);
        d
    }

    /// Attempts since the last [`reset`](Self::reset).
    pub fn attempts(&self) -> u32 {
        self.attempts
    }

    /// After a successful connection: back to [`Self::MIN`].
    pub fn reset(&mut self) {
        *self = Self::new();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn doubles_up_to_the_cap_and_resets() {
        let mut b = Backoff::new();
        let delays: Vec<u64> = (0..7).map(|_| b.next_delay().as_millis() as u64).collect();
        assert_eq!(delays, [100, 200, 400, 800, 1600, 2000, 2000]);
        assert_eq!(b.attempts(), 7);
        b.reset();
        assert_eq!(b.next_delay(), Backoff::MIN);
        assert_eq!(b.attempts(), 1);
    }
}
