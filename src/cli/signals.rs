//! The signals that stop a render gracefully: SIGINT (Ctrl-C), SIGTERM (how batch systems
//! stop a job: Slurm's preemption and time limits, Kubernetes' eviction) and SIGHUP (the
//! terminal went away). The first one asks the render to stop after its current step
//! (docs/CLI.md), which then writes the image, the stats and a checkpoint and exits with
//! 128 + the signal's number (130, 143, 129); a second one ends the process at once with
//! that status.

use signal_hook::consts::{SIGHUP, SIGINT, SIGTERM};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};

/// The signals handled, with their names for messages.
const STOP_SIGNALS: [(i32, &str); 3] = [(SIGINT, "SIGINT"), (SIGTERM, "SIGTERM"), (SIGHUP, "SIGHUP")];

/// Whether a stop was asked for, and by which signal.
#[derive(Clone)]
pub struct StopSignals {
    requested: Arc<AtomicBool>,
    /// The number of the first signal received (0: none yet).
    signal: Arc<AtomicUsize>,
}

impl StopSignals {
    /// Installs the handlers. If the operating system refuses one, that signal keeps its
    /// default action (it ends the process) and a line says so.
    pub fn install() -> StopSignals {
        let stop = StopSignals { requested: Arc::new(AtomicBool::new(false)), signal: Arc::new(AtomicUsize::new(0)) };
        for (signal, name) in STOP_SIGNALS {
            // In this order, for each delivery: a stop already asked for ends the process;
            // otherwise the signal is recorded, then the stop is asked for.
            let installed =
                signal_hook::flag::register_conditional_shutdown(signal, 128 + signal, stop.requested.clone())
                    .and_then(|_| signal_hook::flag::register_usize(signal, stop.signal.clone(), signal as usize))
                    .and_then(|_| signal_hook::flag::register(signal, stop.requested.clone()));
            if let Err(e) = installed {
                super::io::say(&format!("warning: cannot handle {name} ({e}); it will end the run without writing"));
            }
        }
        stop
    }

    /// Whether a stop signal has arrived.
    pub fn requested(&self) -> bool {
        self.requested.load(Ordering::SeqCst)
    }

    /// The exit status of a run that a signal stopped: 128 + its number (130 for SIGINT,
    /// 143 for SIGTERM, 129 for SIGHUP); `None` before any.
    pub fn exit_status(&self) -> Option<u8> {
        match self.signal.load(Ordering::SeqCst) {
            0 => None,
            n => u8::try_from(128 + n).ok(),
        }
    }

    /// The name of the signal received ("SIGTERM"), for messages.
    pub fn name(&self) -> &'static str {
        let n = self.signal.load(Ordering::SeqCst);
        STOP_SIGNALS.iter().find(|(s, _)| *s as usize == n).map_or("a signal", |(_, name)| name)
    }
}
