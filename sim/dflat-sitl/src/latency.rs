//! What the autopilot sees of the controller's timing: pose departure →
//! command arrival and the command stream's inter-arrival jitter, measured
//! by the shell at the sockets ([`LatencyProbe`]); and the one-shot pose
//! faults (a late pose, dropped poses) for the tests, owned by the pure
//! step on the SITL clock ([`PoseFaults`]).
//!
//! **Matching a command to its pose.** The SITL knows when it sent each
//! pose. A command arriving at `c` is matched to the newest pose that
//! departed before `c` and was not matched yet; older unmatched poses are
//! forgotten (superseded). A command with no such pose — a tick that ran on
//! a pose already answered (the deadline fallback, a clock tick between
//! poses) — counts as unmatched. With pose-locked ticks every command
//! follows its pose; with clock ticks a pose that departs between the
//! daemon's tick and the command's arrival (a window of ~0.2 ms per
//! period) is credited to that command although the tick used the previous
//! one: the clock's latency is then slightly underestimated.
//!
//! The pose stream is VISION_POSITION_ESTIMATE when vision is on
//! (`sitl.vision_rate_hz` above 0), else LOCAL_POSITION_NED. The one-shot faults act on
//! LOCAL_POSITION_NED (a delayed pose is sent at the first plant step at or
//! after its due time: to the plant step's resolution, 5 ms at 200 Hz).

use std::collections::VecDeque;
use std::sync::Mutex;
use std::time::{Duration, Instant};

use dflat_link::MavMessage;

/// Samples kept for the percentiles (an hour at 50 Hz is 180 000).
const MAX_SAMPLES: usize = 500_000;
/// Unmatched pose departures kept.
const MAX_DEPARTURES: usize = 64;
/// Command intervals longer than this are stream gaps, not jitter.
const MAX_INTERVAL: Duration = Duration::from_millis(500);

/// Pose → command latency and command cadence as the SITL measured them
/// (part of [`super::SitlCounters`]). Times in µs; 0 when no sample.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct PoseLatency {
    /// Commands matched to a pose (see the module docs).
    pub matched: u64,
    /// Commands that followed no new pose.
    pub unmatched: u64,
    /// Pose departure → command arrival, median \[µs\].
    pub p50_us: u64,
    /// … 99th percentile \[µs\].
    pub p99_us: u64,
    /// … largest \[µs\].
    pub max_us: u64,
    /// Command inter-arrival intervals measured (gaps > 0.5 s excluded).
    pub intervals: u64,
    /// Median command inter-arrival interval \[µs\].
    pub interval_p50_us: u64,
    /// 99th percentile of |interval − median interval| \[µs\]: the jitter
    /// of the command stream at the autopilot.
    pub jitter_p99_us: u64,
    /// Largest command inter-arrival interval \[µs\] (gaps excluded).
    pub interval_max_us: u64,
    /// Poses not sent by [`super::SitlHandle::drop_next_poses`].
    pub poses_dropped: u64,
    /// Poses sent late by [`super::SitlHandle::delay_next_pose`].
    pub poses_delayed: u64,
}

#[derive(Debug, Default)]
struct Inner {
    departures: VecDeque<Instant>,
    last_command: Option<Instant>,
    latency_us: Vec<u32>,
    interval_us: Vec<u32>,
    matched: u64,
    unmatched: u64,
}

/// The shared probe (one per SITL).
#[derive(Debug, Default)]
pub(super) struct LatencyProbe {
    inner: Mutex<Inner>,
}

fn micros(d: Duration) -> u32 {
    u32::try_from(d.as_micros()).unwrap_or(u32::MAX)
}

fn percentile(sorted: &[u32], q: f64) -> u64 {
    if sorted.is_empty() {
        return 0;
    }
    let i = ((sorted.len() - 1) as f64 * q).round() as usize;
    u64::from(sorted[i.min(sorted.len() - 1)])
}

fn push(v: &mut Vec<u32>, x: u32) {
    if v.len() < MAX_SAMPLES {
        v.push(x);
    }
}

impl LatencyProbe {
    fn lock(&self) -> std::sync::MutexGuard<'_, Inner> {
        self.inner.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// A pose of the measured stream left at `at`.
    pub(super) fn pose_sent(&self, at: Instant) {
        let mut g = self.lock();
        if g.departures.len() == MAX_DEPARTURES {
            g.departures.pop_front();
        }
        g.departures.push_back(at);
    }

    /// A command was accepted at `at`.
    pub(super) fn command(&self, at: Instant) {
        let mut g = self.lock();
        if let Some(last) = g.last_command.replace(at) {
            let interval = at.saturating_duration_since(last);
            if interval <= MAX_INTERVAL {
                push(&mut g.interval_us, micros(interval));
            }
        }
        match g.departures.iter().rposition(|d| *d <= at) {
            Some(i) => {
                let d = g.departures[i];
                g.departures.drain(..=i);
                g.matched += 1;
                push(&mut g.latency_us, micros(at.saturating_duration_since(d)));
            }
            None => g.unmatched += 1,
        }
    }

    /// The figures so far (the pose faults' counts are the step's, 0 here).
    pub(super) fn snapshot(&self) -> PoseLatency {
        let g = self.lock();
        let mut lat = g.latency_us.clone();
        let mut iv = g.interval_us.clone();
        let (matched, unmatched) = (g.matched, g.unmatched);
        drop(g);
        lat.sort_unstable();
        iv.sort_unstable();
        let median = percentile(&iv, 0.5);
        let mut dev: Vec<u32> = iv
            .iter()
            .map(|x| u32::try_from(u64::from(*x).abs_diff(median)).unwrap_or(u32::MAX))
            .collect();
        dev.sort_unstable();
        PoseLatency {
            matched,
            unmatched,
            p50_us: percentile(&lat, 0.5),
            p99_us: percentile(&lat, 0.99),
            max_us: lat.last().map_or(0, |x| u64::from(*x)),
            intervals: iv.len() as u64,
            interval_p50_us: median,
            jitter_p99_us: percentile(&dev, 0.99),
            interval_max_us: iv.last().map_or(0, |x| u64::from(*x)),
            poses_dropped: 0,
            poses_delayed: 0,
        }
    }
}

/// What to do with the pose about to be sent ([`PoseFaults::pose_fate`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum PoseFate {
    /// Send it now.
    Send,
    /// Do not send it (dropped).
    Drop,
    /// Hold it; [`PoseFaults::due_delayed`] returns it when due.
    Delay,
}

/// The one-shot pose faults, owned by the pure step (times: seconds on the
/// SITL clock).
#[derive(Debug, Default)]
pub(super) struct PoseFaults {
    drop_next: u32,
    delay_next: Option<f64>,
    delayed: Option<(f64, MavMessage)>,
}

impl PoseFaults {
    /// Whether the LOCAL_POSITION_NED about to be sent at `now` \[s\] goes
    /// now, is dropped or delayed (`msg` is kept for later then).
    pub(super) fn pose_fate(&mut self, now: f64, msg: &MavMessage) -> PoseFate {
        if self.drop_next > 0 {
            self.drop_next -= 1;
            return PoseFate::Drop;
        }
        if let Some(delay) = self.delay_next.take() {
            self.delayed = Some((now + delay, msg.clone()));
            return PoseFate::Delay;
        }
        PoseFate::Send
    }

    /// The delayed pose, once due at `now` \[s\].
    pub(super) fn due_delayed(&mut self, now: f64) -> Option<MavMessage> {
        match &self.delayed {
            Some((due, _)) if *due <= now + 1e-9 => self.delayed.take().map(|(_, m)| m),
            _ => None,
        }
    }

    /// Drop the next `n` poses.
    pub(super) fn drop_next(&mut self, n: u32) {
        self.drop_next = n;
    }

    /// Send the next pose `delay` \[s\] late.
    pub(super) fn delay_next(&mut self, delay: f64) {
        self.delay_next = Some(delay);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ms(x: u64) -> Duration {
        Duration::from_millis(x)
    }

    #[test]
    fn commands_match_the_newest_unanswered_pose() {
        let p = LatencyProbe::default();
        let t0 = Instant::now();
        for k in 0..10u64 {
            p.pose_sent(t0 + ms(20 * k));
            p.command(t0 + ms(20 * k) + Duration::from_micros(200));
        }
        // A tick with no new pose (fallback) is unmatched.
        p.command(t0 + ms(203));
        // Two poses, one command: the newer one is matched.
        p.pose_sent(t0 + ms(220));
        p.pose_sent(t0 + ms(240));
        p.command(t0 + ms(241));
        let s = p.snapshot();
        assert_eq!((s.matched, s.unmatched), (11, 1));
        assert_eq!(s.p50_us, 200);
        assert_eq!(s.max_us, 1000);
        assert_eq!(s.interval_p50_us, 20_000);
    }

    #[test]
    fn drop_and_delay_are_one_shot() {
        let mut p = PoseFaults::default();
        let msg = MavMessage::HEARTBEAT(Default::default());
        p.drop_next(2);
        assert_eq!(p.pose_fate(1.0, &msg), PoseFate::Drop);
        assert_eq!(p.pose_fate(1.0, &msg), PoseFate::Drop);
        assert_eq!(p.pose_fate(1.0, &msg), PoseFate::Send);
        p.delay_next(0.008);
        assert_eq!(p.pose_fate(1.0, &msg), PoseFate::Delay);
        assert_eq!(p.pose_fate(1.0, &msg), PoseFate::Send);
        assert!(p.due_delayed(1.007).is_none());
        assert!(p.due_delayed(1.008).is_some());
        assert!(p.due_delayed(1.009).is_none());
    }
}
