//! Refusals said once, not streamed: a rate limit per sender and reason,
//! shared by the daemon and the SITL (pure: time enters as an argument).
//!
//! The first refusal of a (sender, reason) pair is said at once (a
//! STATUSTEXT, a log line at the caller's level); repeats within
//! [`REFUSAL_REPEAT_S`] are counted and said at most once per interval,
//! with the count of those held back. Callers log repeats at DEBUG.

use std::collections::HashMap;

/// The shortest interval between two texts of one sender and reason \[s\].
pub const REFUSAL_REPEAT_S: f64 = 10.0;

/// At most this many (sender, reason) pairs are remembered; beyond it the
/// oldest-said pair is forgotten (a flood of senders cannot grow memory).
const MAX_KEYS: usize = 256;

/// What to do with one refusal.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Say {
    /// The first of its kind: say it (and log it at the caller's level).
    First,
    /// A repeat, due again: say it with the number of repeats held back
    /// since the last text (log at DEBUG).
    Again {
        /// Repeats not said since the last text.
        held_back: u64,
    },
    /// A repeat within the interval: say nothing (count, DEBUG).
    Quiet,
}

impl Say {
    /// Whether a text goes out.
    pub fn speaks(self) -> bool {
        !matches!(self, Say::Quiet)
    }

    /// `text` as it is said: unchanged the first time, with
    /// "(N more)" appended when repeats were held back.
    pub fn text(self, text: &str) -> String {
        match self {
            Say::Again { held_back } if held_back > 0 => format!("{text} ({held_back} more)"),
            _ => text.to_owned(),
        }
    }
}

#[derive(Debug, Clone, Copy)]
struct Entry {
    last_said: f64,
    held_back: u64,
}

/// The rate limit (see the module docs). `S` identifies a sender.
#[derive(Debug, Clone)]
pub struct RefusalLimiter<S> {
    interval: f64,
    said: HashMap<(S, String), Entry>,
}

impl<S: std::hash::Hash + Eq + Clone> Default for RefusalLimiter<S> {
    fn default() -> Self {
        Self::new(REFUSAL_REPEAT_S)
    }
}

impl<S: std::hash::Hash + Eq + Clone> RefusalLimiter<S> {
    /// A limiter saying each (sender, reason) at most once per `interval` \[s\].
    pub fn new(interval: f64) -> Self {
        Self {
            interval,
            said: HashMap::new(),
        }
    }

    /// A refusal of `reason` to `sender` at time `now` \[s, any monotonic
    /// clock\]: whether and how to say it.
    pub fn refuse(&mut self, sender: S, reason: &str, now: f64) -> Say {
        let key = (sender, reason.to_owned());
        if let Some(e) = self.said.get_mut(&key) {
            if now - e.last_said >= self.interval {
                let held_back = e.held_back;
                *e = Entry {
                    last_said: now,
                    held_back: 0,
                };
                return Say::Again { held_back };
            }
            e.held_back += 1;
            return Say::Quiet;
        }
        if self.said.len() >= MAX_KEYS
            && let Some(oldest) = self
                .said
                .iter()
                .min_by(|a, b| a.1.last_said.total_cmp(&b.1.last_said))
                .map(|(k, _)| k.clone())
        {
            self.said.remove(&oldest);
        }
        self.said.insert(
            key,
            Entry {
                last_said: now,
                held_back: 0,
            },
        );
        Say::First
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn once_per_interval_per_sender_and_reason_with_a_count() {
        let mut l = RefusalLimiter::new(10.0);
        assert_eq!(l.refuse(245u8, "a", 0.0), Say::First);
        assert_eq!(l.refuse(245, "a", 0.4), Say::Quiet);
        assert_eq!(l.refuse(245, "a", 9.9), Say::Quiet);
        // Another reason or another sender is said at once.
        assert_eq!(l.refuse(245, "b", 1.0), Say::First);
        assert_eq!(l.refuse(7, "a", 1.0), Say::First);
        let again = l.refuse(245, "a", 10.0);
        assert_eq!(again, Say::Again { held_back: 2 });
        assert_eq!(again.text("x"), "x (2 more)");
        assert_eq!(l.refuse(245, "a", 20.5), Say::Again { held_back: 0 });
        assert_eq!(Say::Again { held_back: 0 }.text("x"), "x");
        assert!(!Say::Quiet.speaks() && Say::First.speaks());
    }

    #[test]
    fn memory_is_bounded() {
        let mut l = RefusalLimiter::new(10.0);
        for i in 0..1000u32 {
            assert_eq!(l.refuse(i, "a", f64::from(i)), Say::First);
        }
        assert!(l.said.len() <= MAX_KEYS);
    }
}
