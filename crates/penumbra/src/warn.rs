//! Warnings to the user: things the renderer did on its own that change
//! what the user gets (skipped degenerate faces, dropped non-finite samples,
//! a derivative term that an integrator does not estimate). Mitsuba prints
//! such lines through its logger; here they go to one replaceable sink, so
//! that the CLI prints them on stderr and the Python package can turn them
//! into `warnings.warn`. Each warning is emitted once per occasion, with
//! counts, never once per sample.

use std::collections::HashSet;
use std::sync::{Arc, Mutex, RwLock};

/// Receives one warning message (no trailing newline).
pub type WarningSink = dyn Fn(&str) + Send + Sync;

static SINK: RwLock<Option<Arc<WarningSink>>> = RwLock::new(None);

/// Messages the default sink has printed: an optimisation loop repeats the
/// same call, and one line per distinct warning is enough.
static PRINTED: Mutex<Option<HashSet<String>>> = Mutex::new(None);

/// Sends a warning to the installed sink (default: `warning: …` on stderr,
/// each distinct message once per process).
pub fn warn(msg: impl AsRef<str>) {
    let msg = msg.as_ref();
    let sink = SINK.read().ok().and_then(|s| s.clone());
    match sink {
        Some(sink) => sink(msg),
        None => {
            let first = PRINTED
                .lock()
                .map(|mut p| p.get_or_insert_with(HashSet::new).insert(msg.to_string()))
                .unwrap_or(true);
            if first {
                eprintln!("warning: {msg}");
            }
        }
    }
}

/// Replaces the warning sink for the whole process; `None` restores the
/// default (stderr).
pub fn set_warning_sink(sink: Option<Arc<WarningSink>>) {
    if let Ok(mut s) = SINK.write() {
        *s = sink;
    }
}
