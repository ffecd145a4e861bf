//! The control thread: a thin real-time shell around [`ControlCore::step`].
//!
//! Per tick: sleep to the absolute deadline ([`Schedule`]), feed the
//! systemd watchdog, drain the event queue, run the pure step, publish the
//! state, hand the command and texts to the send task (`try_send`: the loop
//! never waits on I/O) and the record to the CSV thread.

use std::sync::Arc;
use std::sync::atomic::{AtomicU8, AtomicU64, Ordering};
use std::time::{Duration, Instant};

use tokio::sync::mpsc;
use tracing::{debug, info};

use super::{ControlReport, Outgoing, ST_SHUTDOWN, Stop, encode_state, notify_status};
use crate::guard::WatchdogCadence;
use crate::records::CsvRecorder;
use crate::schedule::Schedule;
use crate::summary::Histogram;
use crate::tick::{ControlCore, Event, TickTime};

/// The control thread's parts.
pub(super) struct ControlLoop {
    /// The pure step and its state.
    pub core: ControlCore,
    /// Events from the receive task.
    pub events: std::sync::mpsc::Receiver<Event>,
    /// To the send task.
    pub out: mpsc::Sender<Outgoing>,
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
    /// Tick period.
    pub period: Duration,
}

impl ControlLoop {
    fn secs(&self, t: Instant) -> f64 {
        t.saturating_duration_since(self.epoch).as_secs_f64()
    }

    fn send(&self, item: Outgoing, dropped: &mut u64) {
        if self.out.try_send(item).is_err() {
            *dropped += 1;
        }
    }

    /// Runs until stopped; returns what it measured.
    pub fn run(mut self) -> ControlReport {
        let mut schedule = Schedule::new(self.period);
        let mut solve_hist = Histogram::new();
        let mut jitter = Histogram::new();
        let mut outbound_dropped = 0u64;
        // Reused every tick: no allocation once the queue has been seen full.
        let mut batch: Vec<Event> = Vec::with_capacity(64);
        let start = Instant::now();
        self.state
            .store(encode_state(self.core.state()), Ordering::Relaxed);
        // systemd: ready once this loop runs; the watchdog is fed from the
        // loop itself (a stuck loop gets the daemon restarted). No-ops when
        // not under systemd.
        if let Err(e) = sd_notify::notify(&[sd_notify::NotifyState::Ready]) {
            debug!(error = %e, "sd_notify READY failed");
        }
        notify_status(self.core.state());
        let mut watchdog = WatchdogCadence::new(sd_notify::watchdog_enabled());
        if let Some(w) = &watchdog {
            info!(interval = ?w.interval(), "systemd watchdog fed from the control loop");
        }
        let epoch = self.epoch;
        let mut stopwatch = move || epoch.elapsed().as_secs_f64();

        loop {
            let deadline = start + schedule.next_deadline();
            let now = Instant::now();
            if now < deadline {
                std::thread::sleep(deadline - now);
            }
            if self.stop.requested() {
                break;
            }
            let wake = Instant::now();
            if let Some(w) = watchdog.as_mut()
                && w.due(wake)
            {
                let _ = sd_notify::notify(&[sd_notify::NotifyState::Watchdog]);
            }
            let Some(slot) = schedule.on_wake(wake.saturating_duration_since(start)) else {
                continue;
            };
            let _span = tracing::debug_span!("tick", k = slot.tick).entered();
            if slot.missed > 0 {
                debug!(missed = slot.missed, "ticks skipped");
            }
            batch.clear();
            batch.extend(self.events.try_iter());
            let time = TickTime {
                tick: slot.tick,
                t: self.secs(wake),
                scheduled: self.secs(wake - slot.jitter),
                jitter_us: u32::try_from(slot.jitter.as_micros()).unwrap_or(u32::MAX),
            };
            let step = self.core.step(&time, batch.drain(..), &mut stopwatch);
            for tr in &step.transitions {
                self.state.store(encode_state(tr.to), Ordering::Relaxed);
                notify_status(tr.to);
            }
            for text in step.texts {
                self.send(Outgoing::plain(text), &mut outbound_dropped);
            }
            if let Some(sent) = step.command {
                let item = Outgoing {
                    message: sent.message,
                    tick: Some(wake),
                    pose_arrival: sent
                        .pose_arrival
                        .map(|s| self.epoch + Duration::from_secs_f64(s)),
                };
                self.send(item, &mut outbound_dropped);
            }
            if let Some(us) = step.solve_us {
                solve_hist.record(u64::from(us));
            }
            jitter.record(slot.jitter.as_micros().min(u128::from(u64::MAX)) as u64);
            if let Some(csv) = &self.csv {
                csv.record(&step.row);
            }
            self.ticks.fetch_add(1, Ordering::Relaxed);
        }

        // Shutdown: the stream has stopped (this loop no longer runs).
        let now = self.secs(Instant::now());
        info!(state = self.core.state().name(), "control loop stopped");
        for text in self.core.shutdown_texts() {
            self.send(Outgoing::plain(text), &mut outbound_dropped);
        }
        self.state.store(ST_SHUTDOWN, Ordering::Relaxed);
        let csv = self.csv.take().map(CsvRecorder::finish);
        let counts = self.core.counts().clone();
        let supervisor = self.core.supervisor();
        ControlReport {
            ticks: self.ticks.load(Ordering::Relaxed),
            missed: schedule.missed_total(),
            commands: counts.commands,
            control_errors: counts.control_errors,
            outbound_dropped,
            solve: solve_hist,
            jitter,
            time_in_state: supervisor.time_in_states(now),
            state_changes: supervisor.transitions(),
            engagements: supervisor.engagement_counts().0,
            disengagements: supervisor.engagement_counts().1,
            final_state: supervisor.state(),
            csv,
            disturbance: counts.disturbance,
            guards: counts.guards,
            solves: counts.solves,
        }
    }
}
