//! The SITL's plant thread: the thin real-time shell around the pure step
//! ([`SitlCore::step`]). Each turn it sleeps to the next plant step, reads
//! the clock, drains the input channel, steps, publishes the status, the
//! truth and the counters for the handle, sends what the step returns
//! (encoded and signed by the [`Outbox`]) and writes the truth CSV.

use super::*;

/// The plant thread.
pub(super) struct PlantLoop {
    pub(super) shared: Arc<Shared>,
    pub(super) core: SitlCore,
    /// What the receive threads and the handle's hooks send the step.
    pub(super) inputs: Receiver<SitlInput>,
    pub(super) outbox: Outbox,
    /// Keep every truth sample for [`SitlHandle::trace`].
    pub(super) record_trace: bool,
    pub(super) truth_file: Option<(PathBuf, BufWriter<File>)>,
}

impl PlantLoop {
    pub(super) fn run(mut self) -> Result<(), SitlError> {
        let start = self.shared.start;
        let mut rows: u64 = 0;
        let mut csv_error = None;
        while !self.shared.stop.load(Ordering::Relaxed) {
            let next = start + Duration::from_secs_f64(self.core.next_step_time());
            let now = Instant::now();
            if next > now {
                std::thread::sleep(next - now);
            }
            // One clock reading: the step's lag and its time.
            let woke = Instant::now();
            if self.core.status().mode == SitlMode::Offboard {
                // While the commands fly the plant (not while the process
                // and the daemon start).
                self.shared
                    .counters
                    .step_lag(woke.saturating_duration_since(next));
            }
            let clock = woke.saturating_duration_since(start).as_secs_f64();
            let inputs: Vec<SitlInput> = self.inputs.try_iter().collect();
            let out = self.core.step(clock, inputs);
            // What a peer may see in this step's frames is published first
            // (a disarm's ack arrives after `armed()` says so).
            self.shared.counters.add(&out.counts);
            {
                let mut p = lock(&self.shared.published);
                p.status = out.status;
                if let Some(sample) = out.truth {
                    p.truth = sample;
                    if self.record_trace {
                        p.trace.push(sample);
                    }
                }
            }
            for m in &out.messages {
                self.outbox.send(m);
                if m.measured_pose {
                    self.shared.latency.pose_sent(Instant::now());
                }
            }
            if let Some(sample) = out.truth
                && let Some((path, w)) = &mut self.truth_file
            {
                let r = write_truth_row(w, &sample).and_then(|()| {
                    rows += 1;
                    if rows.is_multiple_of(CSV_FLUSH_ROWS) {
                        w.flush()
                    } else {
                        Ok(())
                    }
                });
                if let Err(source) = r {
                    // Keep flying without the record; report at stop.
                    tracing::error!(file = %path.display(), error = %source, "sitl: truth CSV write failed; no more rows");
                    csv_error = Some(SitlError::Truth {
                        file: path.clone(),
                        source,
                    });
                    self.truth_file = None;
                }
            }
        }
        if let Some((path, w)) = &mut self.truth_file {
            w.flush().map_err(|source| SitlError::Truth {
                file: path.clone(),
                source,
            })?;
        }
        csv_error.map_or(Ok(()), Err)
    }
}
