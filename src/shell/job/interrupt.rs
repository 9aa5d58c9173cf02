//! SIGINT and SIGTERM during `study run`: the first one asks the run to stop after the chunks in
//! flight (their rows are written, the file is closed and marked incomplete, and the process
//! exits with 128 + the signal's number); a second one ends the process at once (the checkpoint
//! still makes the file resumable). Other commands keep the default behaviour (they write nothing
//! that a stop could leave half-done: their outputs are atomic).

use signal_hook::consts::{SIGINT, SIGTERM, SIGXFSZ};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};

static SEEN: AtomicBool = AtomicBool::new(false);
static SIGNAL: AtomicUsize = AtomicUsize::new(0);

/// A run stopped by a signal: its file is closed, marked incomplete and resumable.
#[derive(Debug, thiserror::Error)]
#[error("{message}")]
pub struct Interrupted {
    pub signal: i32,
    pub message: String,
}

impl Interrupted {
    /// 128 + the signal's number, as a shell reports a process ended by it (130, 143).
    pub fn exit_code(&self) -> i32 {
        128 + self.signal
    }
}

/// Catches SIGINT and SIGTERM for a run that can stop cleanly ([`requested`]).
pub fn install() -> std::io::Result<()> {
    for sig in [SIGINT, SIGTERM] {
        // Handlers run in the order registered: a second signal exits before the flag is set.
        signal_hook::flag::register_conditional_shutdown(sig, 128 + sig, &SEEN)?;
        signal_hook::flag::register(sig, &SEEN)?;
        signal_hook::flag::register_usize(sig, &SIGNAL, sig as usize)?;
    }
    Ok(())
}

/// The signal that asked the run to stop, if any.
pub fn requested() -> Option<i32> {
    SEEN.load(Ordering::SeqCst)
        .then(|| SIGNAL.load(Ordering::SeqCst) as i32)
}

/// The signal's name for messages.
pub fn name(signal: i32) -> &'static str {
    match signal {
        SIGINT => "SIGINT (Ctrl-C)",
        SIGTERM => "SIGTERM",
        _ => "a signal",
    }
}

/// A write past the file-size limit (`ulimit -f`) fails with "File too large" instead of killing
/// the process with SIGXFSZ, so the error can be reported and the temp file removed.
pub fn ignore_file_size_signal() {
    // SAFETY: the action does nothing, which is async-signal-safe.
    let _ = unsafe { signal_hook::low_level::register(SIGXFSZ, || {}) };
}
