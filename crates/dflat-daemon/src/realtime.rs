//! The control thread's real-time settings: SCHED_FIFO priority, CPU
//! affinity and locked memory, applied through safe APIs (`thread-priority`,
//! `nix`) — no `unsafe` here.
//!
//! All three are optional and off by default. When one is asked for and the
//! system refuses (no `CAP_SYS_NICE`, `RLIMIT_RTPRIO` / `RLIMIT_MEMLOCK`
//! too low, a CPU that does not exist), [`apply_to_current_thread`] returns an
//! error that names the setting and says what to grant; the daemon refuses
//! to start rather than fly with a scheduling it was not configured for. The
//! systemd unit (`deploy/dflat.service`) carries the matching limits
//! (`LimitRTPRIO`, `LimitMEMLOCK`, `CPUAffinity`) commented out.

use serde::{Deserialize, Serialize};
use thiserror::Error;

/// `[realtime]`: how the control thread is scheduled.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(deny_unknown_fields, default)]
pub struct RealtimeConfig {
    /// SCHED_FIFO priority of the control thread, 1–99; 0 = the normal
    /// scheduler (default). PX4 runs its position controller at high FIFO
    /// priority; 80 leaves room above for IRQ threads on a PREEMPT_RT kernel.
    pub fifo_priority: u8,
    /// Pin the control thread to these CPUs (0-based); empty = no pinning
    /// (default). Pin away from the CPU that takes the network interrupts.
    pub cpus: Vec<usize>,
    /// Lock all current and future pages of the process in memory
    /// (`mlockall(MCL_CURRENT | MCL_FUTURE)`), so the tick never waits on a
    /// page fault. Default false.
    pub lock_memory: bool,
}

impl RealtimeConfig {
    /// Whether anything is asked for.
    pub fn is_enabled(&self) -> bool {
        self.fifo_priority > 0 || !self.cpus.is_empty() || self.lock_memory
    }
}

impl RealtimeConfig {
    /// The settings for the daemon's link threads (the async runtime's
    /// workers: receive, send, heartbeat): SCHED_FIFO one below the control
    /// thread, no pinning, no memory locking of their own (`mlockall` is
    /// process-wide). A pose-locked tick waits on the receive task and its
    /// command on the send task: under load they need the priority too.
    /// Nothing asked for: nothing.
    pub fn link_threads(&self) -> RealtimeConfig {
        RealtimeConfig {
            fifo_priority: self.fifo_priority.saturating_sub(1),
            cpus: Vec::new(),
            lock_memory: false,
        }
    }
}

/// A real-time setting the system refused.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum RealtimeError {
    /// `realtime.fifo_priority` could not be applied.
    #[error(
        "realtime.fifo_priority = {priority}: SCHED_FIFO refused ({reason}); run as root, or \
         grant CAP_SYS_NICE or LimitRTPRIO={priority} (deploy/dflat.service), or set 0"
    )]
    Priority {
        /// The priority asked for.
        priority: u8,
        /// The system's answer.
        reason: String,
    },
    /// `realtime.cpus` could not be applied.
    #[error(
        "realtime.cpus = {cpus:?}: CPU affinity refused ({reason}); this machine has {available} CPUs"
    )]
    Affinity {
        /// The CPUs asked for.
        cpus: Vec<usize>,
        /// CPUs online.
        available: usize,
        /// The system's answer.
        reason: String,
    },
    /// `realtime.lock_memory` could not be applied.
    #[error(
        "realtime.lock_memory = true: mlockall refused ({reason}); run as root, or grant \
         LimitMEMLOCK=infinity (deploy/dflat.service), or set false"
    )]
    LockMemory {
        /// The system's answer.
        reason: String,
    },
}

/// What [`apply_to_current_thread`] did, for the log and the summary.
#[derive(Debug, Clone, PartialEq, Eq, Default, Serialize)]
pub struct RealtimeApplied {
    /// SCHED_FIFO priority in effect (0 = normal scheduling).
    pub fifo_priority: u8,
    /// CPUs the thread is pinned to (empty = not pinned).
    pub cpus: Vec<usize>,
    /// Memory locked.
    pub memory_locked: bool,
}

/// Applies `cfg` to the calling thread (priority, affinity) and the process
/// (locked memory). Call it from the control thread before its first tick.
/// Nothing asked for: nothing done, `Ok` with everything off.
pub fn apply_to_current_thread(cfg: &RealtimeConfig) -> Result<RealtimeApplied, RealtimeError> {
    let mut applied = RealtimeApplied::default();
    if cfg.lock_memory {
        use nix::sys::mman::{MlockAllFlags, mlockall};
        mlockall(MlockAllFlags::MCL_CURRENT | MlockAllFlags::MCL_FUTURE).map_err(|e| {
            RealtimeError::LockMemory {
                reason: e.desc().to_owned(),
            }
        })?;
        applied.memory_locked = true;
    }
    if !cfg.cpus.is_empty() {
        use nix::sched::{CpuSet, sched_setaffinity};
        use nix::unistd::Pid;
        let available = std::thread::available_parallelism().map_or(1, |n| n.get());
        let refuse = |reason: String| RealtimeError::Affinity {
            cpus: cfg.cpus.clone(),
            available,
            reason,
        };
        let mut set = CpuSet::new();
        for &cpu in &cfg.cpus {
            set.set(cpu).map_err(|e| refuse(e.desc().to_owned()))?;
        }
        // Pid 0 = the calling thread.
        sched_setaffinity(Pid::from_raw(0), &set).map_err(|e| refuse(e.desc().to_owned()))?;
        applied.cpus = cfg.cpus.clone();
    }
    if cfg.fifo_priority > 0 {
        use thread_priority::{
            RealtimeThreadSchedulePolicy, ThreadPriority, ThreadPriorityValue,
            ThreadSchedulePolicy, set_thread_priority_and_policy, thread_native_id,
        };
        let refuse = |reason: String| RealtimeError::Priority {
            priority: cfg.fifo_priority,
            reason,
        };
        let value =
            ThreadPriorityValue::try_from(cfg.fifo_priority).map_err(|e| refuse(e.to_owned()))?;
        set_thread_priority_and_policy(
            thread_native_id(),
            ThreadPriority::Crossplatform(value),
            ThreadSchedulePolicy::Realtime(RealtimeThreadSchedulePolicy::Fifo),
        )
        .map_err(|e| refuse(format!("{e:?}")))?;
        applied.fifo_priority = cfg.fifo_priority;
    }
    Ok(applied)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn link_threads_run_one_below_the_control_thread_unpinned() {
        let cfg = RealtimeConfig {
            fifo_priority: 80,
            cpus: vec![1],
            lock_memory: true,
        };
        let l = cfg.link_threads();
        assert_eq!(
            (l.fifo_priority, l.cpus.len(), l.lock_memory),
            (79, 0, false)
        );
        assert!(!RealtimeConfig::default().link_threads().is_enabled());
    }

    #[test]
    fn nothing_asked_nothing_done() {
        let cfg = RealtimeConfig::default();
        assert!(!cfg.is_enabled());
        assert_eq!(
            apply_to_current_thread(&cfg).unwrap(),
            RealtimeApplied::default()
        );
    }

    #[test]
    fn a_cpu_that_does_not_exist_is_refused_with_the_field_named() {
        let cfg = RealtimeConfig {
            cpus: vec![100_000],
            ..RealtimeConfig::default()
        };
        // In a thread of its own: a successful pin must not leak into the
        // test harness's threads.
        let err = std::thread::spawn(move || apply_to_current_thread(&cfg))
            .join()
            .unwrap()
            .unwrap_err()
            .to_string();
        assert!(err.contains("realtime.cpus"), "{err}");
    }

    #[test]
    fn pinning_to_cpu_0_works_or_names_the_refusal() {
        let cfg = RealtimeConfig {
            cpus: vec![0],
            ..RealtimeConfig::default()
        };
        match std::thread::spawn(move || apply_to_current_thread(&cfg))
            .join()
            .unwrap()
        {
            Ok(a) => assert_eq!(a.cpus, vec![0]),
            Err(e) => assert!(e.to_string().contains("realtime.cpus"), "{e}"),
        }
    }

    #[test]
    fn fifo_is_applied_or_refused_with_what_to_grant() {
        let cfg = RealtimeConfig {
            fifo_priority: 10,
            ..RealtimeConfig::default()
        };
        match std::thread::spawn(move || apply_to_current_thread(&cfg))
            .join()
            .unwrap()
        {
            Ok(a) => assert_eq!(a.fifo_priority, 10),
            Err(e) => {
                let text = e.to_string();
                assert!(
                    text.contains("realtime.fifo_priority") && text.contains("LimitRTPRIO"),
                    "{text}"
                );
            }
        }
    }
}
