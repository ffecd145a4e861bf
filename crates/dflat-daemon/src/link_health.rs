//! Link-side guards of the daemon: the command slot (the command stream
//! comes first), the rate limit of replies, the liveness of the link tasks
//! and their counters for the summary.
//!
//! * [`CommandSlot`] — SET_ATTITUDE_TARGET has its own one-deep slot between
//!   the control thread and the send task. A newer command replaces one not
//!   yet sent ([`LinkGuardSummary::commands_replaced`]); the send task drops
//!   a command older than one tick ([`LinkGuardSummary::commands_stale`]).
//!   Replies never queue in front of it.
//! * [`ReplyBudget`] — replies (COMMAND_ACK, STATUSTEXT answers, refusals)
//!   go through their own bounded queue and leave at most
//!   [`REPLY_RATE_HZ`] per second (bursts of [`REPLY_BURST`]); the rest is
//!   dropped and counted ([`LinkGuardSummary::replies_dropped`]).
//! * [`LinkHealth`] — the receive, send and heartbeat tasks each mark
//!   themselves alive every [`BEAT_INTERVAL`]. The control loop checks them
//!   every tick; one silent for [`STALL_LIMIT`] is a stalled (or dead)
//!   task: the systemd watchdog is no longer fed (and `WATCHDOG=trigger`
//!   asks systemd to act now), HEARTBEAT reports MAV_STATE_CRITICAL and a
//!   STATUSTEXT says which task.

use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::{Duration, Instant};

use serde::Serialize;

/// How often each link task marks itself alive.
pub const BEAT_INTERVAL: Duration = Duration::from_millis(100);
/// A link task silent this long is stalled.
pub const STALL_LIMIT: Duration = Duration::from_millis(500);
/// Replies per second the send task lets out (sustained).
pub const REPLY_RATE_HZ: f64 = 20.0;
/// Replies the send task lets out back to back.
pub const REPLY_BURST: f64 = 10.0;
/// Capacity of the replies queue \[messages\]; beyond it replies are dropped.
pub const REPLY_QUEUE: usize = 32;

/// One of the daemon's link tasks.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LinkTask {
    /// Frames in: authentication, filter, events, answers.
    Receive,
    /// Frames out: commands, replies, heartbeats.
    Send,
    /// The 1 Hz HEARTBEAT.
    Heartbeat,
}

impl LinkTask {
    /// All tasks, in [`Self::index`] order.
    pub const ALL: [LinkTask; 3] = [LinkTask::Receive, LinkTask::Send, LinkTask::Heartbeat];

    /// Index into per-task arrays.
    pub fn index(self) -> usize {
        match self {
            LinkTask::Receive => 0,
            LinkTask::Send => 1,
            LinkTask::Heartbeat => 2,
        }
    }

    /// Lower-case name (`receive`, `send`, `heartbeat`).
    pub fn name(self) -> &'static str {
        match self {
            LinkTask::Receive => "receive",
            LinkTask::Send => "send",
            LinkTask::Heartbeat => "heartbeat",
        }
    }

    /// Parses [`Self::name`].
    pub fn parse(s: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|t| t.name() == s.trim())
    }
}

/// Liveness of the link tasks, shared by them and the control loop.
#[derive(Debug)]
pub struct LinkHealth {
    epoch: Instant,
    /// Last beat per task \[ms since `epoch`\].
    beats: [AtomicU64; 3],
    /// Set once a stall was found: HEARTBEAT says CRITICAL.
    fault: AtomicBool,
    stalls: AtomicU64,
}

impl LinkHealth {
    /// All tasks alive as of `epoch`.
    pub fn new(epoch: Instant) -> Self {
        Self {
            epoch,
            beats: Default::default(),
            fault: AtomicBool::new(false),
            stalls: AtomicU64::new(0),
        }
    }

    fn ms(&self, t: Instant) -> u64 {
        u64::try_from(t.saturating_duration_since(self.epoch).as_millis()).unwrap_or(u64::MAX)
    }

    /// `task` is alive at `now`.
    pub fn beat(&self, task: LinkTask, now: Instant) {
        self.beats[task.index()].store(self.ms(now), Ordering::Relaxed);
    }

    /// The first task silent for more than [`STALL_LIMIT`] at `now`, if any.
    pub fn stalled(&self, now: Instant) -> Option<LinkTask> {
        let now = self.ms(now);
        let limit = u64::try_from(STALL_LIMIT.as_millis()).unwrap_or(u64::MAX);
        LinkTask::ALL
            .into_iter()
            .find(|t| now.saturating_sub(self.beats[t.index()].load(Ordering::Relaxed)) > limit)
    }

    /// Records a stall (once per task fault): HEARTBEAT reports CRITICAL.
    pub fn set_fault(&self) {
        if !self.fault.swap(true, Ordering::Relaxed) {
            self.stalls.fetch_add(1, Ordering::Relaxed);
        }
    }

    /// A link task stalled or died.
    pub fn fault(&self) -> bool {
        self.fault.load(Ordering::Relaxed)
    }

    /// Stalls found.
    pub fn stalls(&self) -> u64 {
        self.stalls.load(Ordering::Relaxed)
    }
}

/// Token bucket for replies: `rate` per second, at most `burst` at once.
/// Pure: time enters as seconds.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ReplyBudget {
    tokens: f64,
    rate: f64,
    burst: f64,
    last: f64,
}

impl ReplyBudget {
    /// A full bucket at time `t` \[s\].
    pub fn new(rate: f64, burst: f64, t: f64) -> Self {
        Self {
            tokens: burst,
            rate,
            burst,
            last: t,
        }
    }

    fn refill(&mut self, t: f64) {
        if t > self.last {
            self.tokens = (self.tokens + (t - self.last) * self.rate).min(self.burst);
            self.last = t;
        }
    }

    /// Whether a reply may go at `t` \[s\]; takes a token if so.
    pub fn take(&mut self, t: f64) -> bool {
        self.refill(t);
        if self.tokens >= 1.0 {
            self.tokens -= 1.0;
            true
        } else {
            false
        }
    }

    /// Whether a reply could go at `t` without taking a token.
    pub fn available(&mut self, t: f64) -> bool {
        self.refill(t);
        self.tokens >= 1.0
    }
}

/// The one-deep slot of SET_ATTITUDE_TARGET between the control thread and
/// the send task.
#[derive(Debug)]
pub struct CommandSlot<T> {
    item: Mutex<Option<T>>,
    notify: tokio::sync::Notify,
    replaced: AtomicU64,
}

impl<T> Default for CommandSlot<T> {
    fn default() -> Self {
        Self {
            item: Mutex::new(None),
            notify: tokio::sync::Notify::new(),
            replaced: AtomicU64::new(0),
        }
    }
}

impl<T> CommandSlot<T> {
    /// Puts `item` in the slot (from any thread, never blocks); an unsent
    /// older one is replaced and counted.
    pub fn put(&self, item: T) {
        let old = self
            .item
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .replace(item);
        if old.is_some() {
            self.replaced.fetch_add(1, Ordering::Relaxed);
        }
        self.notify.notify_one();
    }

    /// Takes what is in the slot.
    pub fn take(&self) -> Option<T> {
        self.item.lock().unwrap_or_else(|p| p.into_inner()).take()
    }

    /// Resolves after the next [`put`](Self::put) (or at once if one
    /// happened since the last wait).
    pub async fn notified(&self) {
        self.notify.notified().await;
    }

    /// Commands replaced before they were sent.
    pub fn replaced(&self) -> u64 {
        self.replaced.load(Ordering::Relaxed)
    }
}

/// What the link guards counted, for the summary.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize)]
pub struct LinkGuardSummary {
    /// Frames or datagrams from an address other than the peer, dropped
    /// (udpin before the lock included; udpout: the kernel drops most
    /// before they are seen).
    pub foreign_frames: u64,
    /// The locked `udpin` peer, if any.
    pub peer: Option<std::net::SocketAddr>,
    /// TCP / serial reconnections.
    pub reconnects: u64,
    /// Frames dropped by the transport (serial queue full, link down).
    pub send_dropped: u64,
    /// Signing on: signed frames with a timestamp more than a minute ahead
    /// of the clock, refused.
    pub future_timestamp: u64,
    /// Commands replaced in the slot by a newer one before they were sent.
    pub commands_replaced: u64,
    /// Commands older than one tick when the send task got to them: dropped.
    pub commands_stale: u64,
    /// Replies dropped (queue full or over the rate limit).
    pub replies_dropped: u64,
    /// Replies sent.
    pub replies_sent: u64,
    /// Link-task stalls found (watchdog no longer fed after the first).
    pub link_stalls: u64,
}

/// The test-only stall hook: `DFLAT_TEST_STALL_TASK=receive|send|heartbeat`
/// and `DFLAT_TEST_STALL_AFTER_S=SECONDS` make that task stop working (and
/// stop marking itself alive) that long after start. For the liveness test
/// only; never set it on a vehicle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StallHook {
    /// The task that stalls.
    pub task: LinkTask,
    /// When, after the daemon's start \[s\].
    pub after_s: f64,
}

impl StallHook {
    /// From the environment (`None` when unset or malformed).
    pub fn from_env() -> Option<Self> {
        let task = LinkTask::parse(&std::env::var("DFLAT_TEST_STALL_TASK").ok()?)?;
        let after_s = std::env::var("DFLAT_TEST_STALL_AFTER_S")
            .ok()
            .and_then(|v| v.trim().parse::<f64>().ok())
            .filter(|v| v.is_finite() && *v >= 0.0)
            .unwrap_or(1.0);
        Some(Self { task, after_s })
    }

    /// Whether `task` should be stalled `elapsed` after start.
    pub fn due(hook: Option<Self>, task: LinkTask, elapsed: Duration) -> bool {
        hook.is_some_and(|h| h.task == task && elapsed.as_secs_f64() >= h.after_s)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reply_budget_bursts_then_limits_to_the_rate() {
        let mut b = ReplyBudget::new(20.0, 10.0, 0.0);
        let burst = (0..100).filter(|_| b.take(0.0)).count();
        assert_eq!(burst, 10);
        // 1 s at 2 kHz of requests: 20 more go.
        // (The 20th token is complete at t = 1 s exactly: rounding may leave
        // it a hair short.)
        let later = (1..=2000).filter(|k| b.take(*k as f64 / 2000.0)).count();
        assert!((19..=20).contains(&later), "{later} replies in 1 s at 20/s");
        assert!(!b.available(1.0));
        assert!(b.available(1.06));
    }

    #[test]
    fn slot_keeps_the_newest_and_counts_replacements() {
        let slot = CommandSlot::default();
        slot.put(1);
        slot.put(2);
        slot.put(3);
        assert_eq!(slot.take(), Some(3));
        assert_eq!(slot.take(), None);
        assert_eq!(slot.replaced(), 2);
    }

    #[test]
    fn a_silent_task_is_stalled() {
        let t0 = Instant::now();
        let h = LinkHealth::new(t0);
        for task in LinkTask::ALL {
            h.beat(task, t0 + Duration::from_millis(400));
        }
        assert_eq!(h.stalled(t0 + Duration::from_millis(800)), None);
        h.beat(LinkTask::Receive, t0 + Duration::from_millis(1000));
        h.beat(LinkTask::Heartbeat, t0 + Duration::from_millis(1000));
        assert_eq!(
            h.stalled(t0 + Duration::from_millis(1000)),
            Some(LinkTask::Send)
        );
        assert!(!h.fault());
        h.set_fault();
        h.set_fault();
        assert!(h.fault());
        assert_eq!(h.stalls(), 1);
        assert_eq!(LinkTask::parse("receive"), Some(LinkTask::Receive));
        assert_eq!(LinkTask::parse("nope"), None);
    }
}
