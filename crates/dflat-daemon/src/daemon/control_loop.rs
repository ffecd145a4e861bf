//! The control thread: a thin real-time shell around [`ControlCore::step`].
//!
//! The loop decides *when* to step, the core *what* to do: it waits on the
//! event queue until the [`TickPlanner`] says a tick is due — the moment a
//! fresh pose arrives (`controller.tick = "pose"`, phase-locked to the
//! stream) or the tick's deadline (the fallback, or `"clock"`). Per tick:
//! feed the systemd watchdog, hand the events since the previous tick to
//! the pure step, publish the state, hand the command and texts to the send
//! task (`try_send`: the loop never waits on I/O) and the record to the CSV
//! thread.
//!
//! Before the first tick the thread applies `[realtime]` (SCHED_FIFO,
//! affinity, locked memory) and reports the outcome to [`super::spawn`],
//! which refuses to start when the system refused.

use std::sync::Arc;
use std::sync::atomic::{AtomicU8, AtomicU64, Ordering};
use std::sync::mpsc::RecvTimeoutError;
use std::time::{Duration, Instant};

use tokio::sync::mpsc;
use tracing::{debug, error, info, warn};

use super::{ControlReport, Outgoing, ST_SHUTDOWN, Stop, encode_state, notify_status};
use crate::guard::WatchdogCadence;
use crate::link_health::{CommandSlot, LinkHealth};
use crate::realtime::{RealtimeApplied, RealtimeConfig, RealtimeError, apply_to_current_thread};
use crate::records::CsvRecorder;
use crate::schedule::{POSE_TIMEOUT_MIN_INTERVALS, TickCause, TickPlanner, pose_timeout_too_tight};
use crate::summary::Histogram;
use crate::tick::{BATCH_MARGIN, ControlCore, Event, StepOutput, TickTime};

/// A graceful stop ends at the latest this long \[s\] after its brake
/// and level were due (a failsafe or a stalled pose stream meanwhile).
pub const STOP_MARGIN: f64 = 0.5;

/// The control thread's parts.
pub(super) struct ControlLoop {
    /// The pure step and its state.
    pub core: ControlCore,
    /// Events from the receive task.
    pub events: std::sync::mpsc::Receiver<Event>,
    /// Missions the receive task's mission protocol accepted (`None`:
    /// cleared), loaded before the tick's events.
    pub missions: std::sync::mpsc::Receiver<Option<crate::mission::Mission>>,
    /// To the send task (texts).
    pub out: mpsc::Sender<Outgoing>,
    /// The command slot of the send task.
    pub commands: Arc<CommandSlot<Outgoing>>,
    /// Liveness of the link tasks: a stalled one stops the watchdog.
    pub health: Arc<LinkHealth>,
    /// Stop request.
    pub stop: Arc<Stop>,
    /// Published state (HEARTBEAT, [`super::DaemonHandle::state`]).
    pub state: Arc<AtomicU8>,
    /// Ticks run.
    pub ticks: Arc<AtomicU64>,
    /// The daemon's epoch: event and tick times are seconds since it.
    pub epoch: Instant,
    /// The flight CSV, if recorded.
    pub csv: Option<CsvRecorder>,
    /// The records' budget: its disk / quota notices are said here, once.
    pub records: Arc<dflat_link::records::RecordBudget>,
    /// Tick period.
    pub period: Duration,
    /// Lock the ticks to the pose stream (`controller.tick = "pose"`).
    pub pose_lock: bool,
    /// How long a tick waits for an expected pose \[s\].
    pub pose_wait: f64,
    /// `safety.pose_timeout_ms` \[s\], checked against the pose stream's
    /// period once it settles ([`pose_timeout_too_tight`]).
    pub pose_timeout: f64,
    /// Real-time settings for this thread.
    pub realtime: RealtimeConfig,
    /// Where the outcome of applying them goes (the daemon's start waits).
    pub realtime_result:
        Option<tokio::sync::oneshot::Sender<Result<RealtimeApplied, RealtimeError>>>,
}

/// What the loop measured, for its report.
struct Meters {
    planner: TickPlanner,
    realtime: RealtimeApplied,
    solve: Histogram,
    jitter: Histogram,
    outbound_dropped: u64,
}

impl ControlLoop {
    /// An event for the next tick; a pose also tells the planner.
    fn take(&self, event: Event, planner: &mut TickPlanner, batch: &mut Vec<Event>) {
        if let Event::Pose { arrival, .. } = &event {
            planner.on_pose(*arrival);
        }
        batch.push(event);
    }

    fn secs(&self, t: Instant) -> f64 {
        t.saturating_duration_since(self.epoch).as_secs_f64()
    }

    fn send(&self, item: Outgoing, dropped: &mut u64) {
        if self.out.try_send(item).is_err() {
            *dropped += 1;
        }
    }

    /// Runs until stopped; returns what it measured. Returns at once (no
    /// tick run) when `[realtime]` was refused.
    pub fn run(mut self) -> ControlReport {
        let (realtime, refused) = self.apply_realtime();
        let period = self.period.as_secs_f64();
        let mut planner = TickPlanner::new(
            period,
            self.pose_wait,
            self.pose_lock,
            self.secs(Instant::now()),
        );
        let mut solve_hist = Histogram::new();
        let mut jitter = Histogram::new();
        let mut outbound_dropped = 0u64;
        // Reused every tick: no allocation once the queue has been seen full.
        let mut batch: Vec<Event> = Vec::with_capacity(64);
        self.state
            .store(encode_state(self.core.state()), Ordering::Relaxed);
        // systemd: ready once this loop runs; the watchdog is fed from the
        // loop itself (a stuck loop gets the daemon restarted). No-ops when
        // not under systemd.
        if !refused && let Err(e) = sd_notify::notify(&[sd_notify::NotifyState::Ready]) {
            debug!(error = %e, "sd_notify READY failed");
        }
        notify_status(self.core.state());
        let mut watchdog = WatchdogCadence::new(sd_notify::watchdog_enabled());
        if let Some(w) = &watchdog {
            info!(interval = ?w.interval(), "systemd watchdog fed from the control loop");
        }
        let epoch = self.epoch;
        let mut stopwatch = move || epoch.elapsed().as_secs_f64();

        // The graceful stop's bound \[s\] after it was asked for.
        let stop_bound = self.core.stop_bound() + STOP_MARGIN;
        let mut stop_asked_at: Option<f64> = None;
        let mut pose_timeout_checked = false;
        while !self.stop.requested() {
            self.wait(&mut planner, &mut batch);
            if self.stop.requested() {
                break;
            }
            let wake = Instant::now();
            let Some(slot) = planner.poll(self.secs(wake)) else {
                continue;
            };
            self.check_health(wake, watchdog.as_mut(), &mut outbound_dropped);
            if !pose_timeout_checked && let Some(p) = planner.settled_pose_period() {
                pose_timeout_checked = true;
                self.check_pose_timeout(p, &mut outbound_dropped);
            }
            let _span = tracing::debug_span!("tick", k = slot.tick).entered();
            if slot.missed > 0 {
                debug!(missed = slot.missed, "ticks skipped");
            }
            if slot.fallback {
                debug!("expected pose late or lost: deadline fallback");
            }
            let lateness = Duration::from_secs_f64(slot.lateness);
            // The tick's time: a pose tick's is its pose's arrival, and it
            // takes the events up to it — exactly those queued before the
            // pose (the receive task queues in arrival order), so the batch
            // does not depend on how soon this thread woke and a replay
            // from the logs finds the same one. Later ones (the ATTITUDE
            // sent with the pose) wait for the next tick.
            let t = match slot.cause {
                TickCause::Pose => (slot.due + BATCH_MARGIN).min(self.secs(wake)),
                TickCause::Deadline => self.secs(wake),
            };
            let taken = batch
                .iter()
                .position(|e| e.arrival() > t)
                .unwrap_or(batch.len());
            for e in &batch[taken..] {
                if let Event::Pose { arrival, .. } = e {
                    planner.on_pose(*arrival);
                }
            }
            let time = TickTime {
                tick: slot.tick,
                t,
                scheduled: slot.due,
                jitter_us: u32::try_from(lateness.as_micros()).unwrap_or(u32::MAX),
            };
            while let Ok(mission) = self.missions.try_recv() {
                self.core.load_mission(t, mission);
            }
            if self.stop.asked() && stop_asked_at.is_none() {
                stop_asked_at = Some(t);
                self.core.begin_stop(t);
            }
            let step = self.core.step(&time, batch.drain(..taken), &mut stopwatch);
            let step = self.publish(step, wake, &mut outbound_dropped);
            if let Some(us) = step.solve_us {
                solve_hist.record(u64::from(us));
            }
            // Wake lateness: after the deadline, or after the pose's
            // arrival (the queue's hand-over) for pose ticks.
            jitter.record(lateness.as_micros().min(u128::from(u64::MAX)) as u64);
            if let Some(csv) = &self.csv {
                csv.record(&step.row);
            }
            self.ticks.fetch_add(1, Ordering::Relaxed);
            if let Some(asked) = stop_asked_at
                && (self.core.stop_done(t) || t - asked >= stop_bound)
            {
                break;
            }
        }

        self.finish(Meters {
            planner,
            realtime,
            solve: solve_hist,
            jitter,
            outbound_dropped,
        })
    }

    /// Applies `[realtime]` to this thread and reports the outcome to the
    /// start; refused, the stop is requested. Returns what was applied and
    /// whether it was refused.
    fn apply_realtime(&mut self) -> (RealtimeApplied, bool) {
        let applied = apply_to_current_thread(&self.realtime);
        let refused = applied.is_err();
        let realtime = applied.clone().unwrap_or_default();
        if let Some(tx) = self.realtime_result.take() {
            let _ = tx.send(applied);
        }
        if refused {
            // spawn() reports the refusal and stops the other parts.
            self.stop.request();
        } else if self.realtime.is_enabled() {
            info!(?realtime, "control thread real-time settings applied");
        }
        (realtime, refused)
    }

    /// Waits for events until the planner's next wake time (pose-locked: a
    /// pose may run the tick now), then takes what is queued.
    fn wait(&self, planner: &mut TickPlanner, batch: &mut Vec<Event>) {
        // Wait: for events (pose-locked: a pose may run the tick now)
        // until the planner's next wake time.
        let wake_at = self.epoch + Duration::from_secs_f64(planner.wake_at().max(0.0));
        let now = Instant::now();
        if now < wake_at {
            if self.pose_lock {
                match self.events.recv_timeout(wake_at - now) {
                    Ok(event) => self.take(event, planner, batch),
                    Err(RecvTimeoutError::Timeout) => {}
                    // The receive task is gone (shutdown): keep time.
                    Err(RecvTimeoutError::Disconnected) => std::thread::sleep(wake_at - now),
                }
            } else {
                std::thread::sleep(wake_at - now);
            }
        }
        while let Ok(event) = self.events.try_recv() {
            self.take(event, planner, batch);
        }
    }

    /// A stalled or dead link task: the watchdog is no longer fed (systemd
    /// restarts the daemon), HEARTBEAT says CRITICAL. Else the watchdog is
    /// fed when due.
    fn check_health(
        &self,
        wake: Instant,
        watchdog: Option<&mut WatchdogCadence>,
        outbound_dropped: &mut u64,
    ) {
        if !self.health.fault()
            && let Some(task) = self.health.stalled(wake)
        {
            self.health.set_fault();
            error!(
                task = task.name(),
                "link task stalled: watchdog no longer fed"
            );
            let _ = sd_notify::notify(&[sd_notify::NotifyState::WatchdogTrigger]);
            let text = dflat_link::statustext(
                dflat_link::dialect::MavSeverity::MAV_SEVERITY_CRITICAL,
                &format!("dflat: link task {} stalled", task.name()),
            );
            self.send(Outgoing::plain(text), outbound_dropped);
        }
        if !self.health.fault()
            && let Some(w) = watchdog
            && w.due(wake)
        {
            let _ = sd_notify::notify(&[sd_notify::NotifyState::Watchdog]);
        }
    }

    /// Says once (log and STATUSTEXT) when `safety.pose_timeout_ms` is
    /// under [`POSE_TIMEOUT_MIN_INTERVALS`] of the pose stream's settled
    /// period `pose_period` \[s\]: one lost pose can then trip the
    /// stale-pose failsafe.
    fn check_pose_timeout(&self, pose_period: f64, outbound_dropped: &mut u64) {
        if !pose_timeout_too_tight(self.pose_timeout, pose_period) {
            return;
        }
        let (timeout_ms, period_ms) = (1e3 * self.pose_timeout, 1e3 * pose_period);
        warn!(
            pose_timeout_ms = timeout_ms,
            pose_period_ms = period_ms,
            "safety.pose_timeout_ms is under {POSE_TIMEOUT_MIN_INTERVALS} of the pose stream's \
             intervals: one lost pose can trip the stale-pose failsafe (docs/safety.md, \"Losing pose\")"
        );
        let text = dflat_link::statustext(
            dflat_link::dialect::MavSeverity::MAV_SEVERITY_WARNING,
            &format!(
                "dflat: pose timeout {timeout_ms:.0}ms < {POSE_TIMEOUT_MIN_INTERVALS}x period {period_ms:.0}ms"
            ),
        );
        self.send(Outgoing::plain(text), outbound_dropped);
    }

    /// Hands a step's outputs on: state changes published, texts and the
    /// records' notices queued, the command into its slot.
    fn publish(&self, step: StepOutput, wake: Instant, outbound_dropped: &mut u64) -> StepOutput {
        let mut step = step;
        for tr in &step.transitions {
            self.state.store(encode_state(tr.to), Ordering::Relaxed);
            notify_status(tr.to);
        }
        for text in std::mem::take(&mut step.texts) {
            self.send(Outgoing::plain(text), outbound_dropped);
        }
        let notices = self.records.take_notices();
        if notices != 0 {
            for (severity, text) in crate::record_store::notice_texts(notices) {
                let text = dflat_link::statustext(severity, text);
                self.send(Outgoing::plain(text), outbound_dropped);
            }
        }
        if let Some(sent) = step.command.take() {
            let item = Outgoing {
                message: sent.message,
                tick: Some(wake),
                pose_arrival: sent
                    .pose_arrival
                    .map(|s| self.epoch + Duration::from_secs_f64(s)),
            };
            self.commands.put(item);
        }
        step
    }

    /// Shutdown, once the stream has stopped: the last texts, the state,
    /// the stop request to the other parts, and the report.
    fn finish(mut self, meters: Meters) -> ControlReport {
        let Meters {
            planner,
            realtime,
            solve: solve_hist,
            jitter,
            mut outbound_dropped,
        } = meters;
        // Shutdown: the stream has stopped (this loop no longer runs).
        let now = self.secs(Instant::now());
        info!(state = self.core.state().name(), "control loop stopped");
        for text in self.core.shutdown_texts() {
            self.send(Outgoing::plain(text), &mut outbound_dropped);
        }
        self.state.store(ST_SHUTDOWN, Ordering::Relaxed);
        // The stream is over: the link tasks may stop (a graceful stop ends
        // here, after its brake and level).
        self.stop.request();
        let csv = self.csv.take().map(CsvRecorder::finish);
        let counts = self.core.counts().clone();
        let supervisor = self.core.supervisor();
        let (engagements, disengagements) = supervisor.engagement_counts();
        ControlReport {
            ticks: self.ticks.load(Ordering::Relaxed),
            missed: planner.counts().missed,
            tick_counts: planner.counts(),
            realtime,
            commands: counts.commands,
            control_errors: counts.control_errors,
            outbound_dropped,
            solve: solve_hist,
            jitter,
            time_in_state: self.core.time_in_states_before_stop(now),
            state_changes: self.core.transitions_before_stop(),
            stop: self.core.stop_summary(),
            engagements,
            disengagements,
            final_state: self.core.state_at_stop().unwrap_or(supervisor.state()),
            csv,
            disturbance: counts.disturbance,
            guards: counts.guards,
            solves: counts.solves,
            pose_window: self.core.window_stats(),
            autopilot_streams: self.core.stream_outcomes(),
        }
    }
}
