//! The control loop's tick schedule: absolute deadlines, missed-tick
//! accounting. Pure (the caller reads the clock and sleeps).
//!
//! Tick `k` is due at `start + k·δt`. The loop sleeps until the next
//! deadline and reports the time it actually woke. If it wakes at or after
//! the deadline of a *later* tick (a stall longer than one period), the
//! ticks in between are skipped and counted — never run in a burst — and the
//! schedule stays anchored to `start` (no drift).

use std::time::Duration;

/// One scheduled tick as decided by [`Schedule::on_wake`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TickSlot {
    /// Index of the tick to run now (deadline `start + tick·δt`).
    pub tick: u64,
    /// Ticks skipped just before this one (0 when on time).
    pub missed: u64,
    /// Wake time minus this tick's deadline (≥ 0, < δt).
    pub jitter: Duration,
}

/// Absolute-deadline schedule of a periodic loop.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Schedule {
    period: Duration,
    next: u64,
    missed_total: u64,
}

impl Schedule {
    /// A schedule with period δt (must be > 0; a zero period is raised to 1 ns).
    pub fn new(period: Duration) -> Self {
        Self {
            period: period.max(Duration::from_nanos(1)),
            next: 0,
            missed_total: 0,
        }
    }

    /// The period δt.
    pub fn period(&self) -> Duration {
        self.period
    }

    /// Deadline of tick `k`, as an offset from the start.
    pub fn deadline(&self, k: u64) -> Duration {
        // Exact in nanoseconds (saturates after ~584 years).
        let ns = self.period.as_nanos().saturating_mul(u128::from(k));
        Duration::from_nanos(u64::try_from(ns).unwrap_or(u64::MAX))
    }

    /// Offset from the start at which the loop should next wake.
    pub fn next_deadline(&self) -> Duration {
        self.deadline(self.next)
    }

    /// Ticks skipped so far.
    pub fn missed_total(&self) -> u64 {
        self.missed_total
    }

    /// The loop woke at `wake` (offset from the start). Returns the tick to
    /// run, or `None` if it woke early (sleep again until
    /// [`next_deadline`](Self::next_deadline)).
    pub fn on_wake(&mut self, wake: Duration) -> Option<TickSlot> {
        let due = self.next_deadline();
        if wake < due {
            return None;
        }
        // Latest tick whose deadline is at or before `wake`.
        let latest = u64::try_from(wake.as_nanos() / self.period.as_nanos()).unwrap_or(u64::MAX);
        let tick = latest.max(self.next);
        let missed = tick - self.next;
        self.missed_total += missed;
        self.next = tick + 1;
        Some(TickSlot {
            tick,
            missed,
            jitter: wake - self.deadline(tick),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ms(x: u64) -> Duration {
        Duration::from_millis(x)
    }
    fn us(x: u64) -> Duration {
        Duration::from_micros(x)
    }

    #[test]
    fn on_time_wakes_run_every_tick_with_their_jitter() {
        let mut s = Schedule::new(ms(20));
        let wakes = [us(50), us(20_100), us(40_000), us(60_900)];
        let slots: Vec<_> = wakes.iter().map(|w| s.on_wake(*w).unwrap()).collect();
        assert_eq!(
            slots.iter().map(|t| t.tick).collect::<Vec<_>>(),
            [0, 1, 2, 3]
        );
        assert!(slots.iter().all(|t| t.missed == 0));
        assert_eq!(slots[1].jitter, us(100));
        assert_eq!(slots[3].jitter, us(900));
        assert_eq!(s.missed_total(), 0);
        assert_eq!(s.next_deadline(), ms(80));
    }

    #[test]
    fn early_wake_is_not_a_tick() {
        let mut s = Schedule::new(ms(20));
        assert!(s.on_wake(ms(0)).is_some());
        assert_eq!(s.on_wake(us(19_999)), None);
        assert_eq!(s.on_wake(ms(20)).unwrap().tick, 1);
    }

    #[test]
    fn a_stall_skips_and_counts_without_burst_or_drift() {
        let mut s = Schedule::new(ms(20));
        s.on_wake(ms(0)).unwrap();
        // Stalled until 95 ms: ticks 1, 2, 3 are missed, tick 4 runs late by 15 ms.
        let slot = s.on_wake(ms(95)).unwrap();
        assert_eq!(
            slot,
            TickSlot {
                tick: 4,
                missed: 3,
                jitter: ms(15)
            }
        );
        // Next deadline stays on the grid: 100 ms, not 95 + 20.
        assert_eq!(s.next_deadline(), ms(100));
        assert_eq!(s.on_wake(us(100_010)).unwrap().missed, 0);
        assert_eq!(s.missed_total(), 3);
    }

    #[test]
    fn late_by_less_than_a_period_is_jitter_not_a_miss() {
        let mut s = Schedule::new(ms(20));
        s.on_wake(ms(0)).unwrap();
        let slot = s.on_wake(us(39_999)).unwrap();
        assert_eq!((slot.tick, slot.missed), (1, 0));
        assert_eq!(slot.jitter, us(19_999));
        // Exactly on the next deadline: one missed.
        let slot = s.on_wake(ms(80)).unwrap();
        assert_eq!((slot.tick, slot.missed), (4, 2));
    }

    #[test]
    fn pure_over_a_sequence_of_wake_times() {
        // 50 Hz with a 1-second stall in the middle.
        let mut s = Schedule::new(ms(20));
        let mut ran = Vec::new();
        for k in 0..10u64 {
            ran.push(s.on_wake(ms(20 * k) + us(30)).unwrap().tick);
        }
        ran.push(s.on_wake(ms(1_200) + us(30)).unwrap().tick);
        for k in 61..64u64 {
            ran.push(s.on_wake(ms(20 * k) + us(30)).unwrap().tick);
        }
        assert_eq!(ran[9..], [9, 60, 61, 62, 63]);
        assert_eq!(s.missed_total(), 50);
    }
}
