//! SIGINT and SIGTERM, caught for the run loop to stop at the middle of a step.

/// SIGINT and SIGTERM set a flag the run loop checks in the middle of every step; a second signal ends the
/// process at once. Unregistered when dropped, so a library caller keeps its own handlers.
pub(super) struct Signals {
    flag: std::sync::Arc<std::sync::atomic::AtomicUsize>,
    ids: Vec<signal_hook::SigId>,
}

impl Signals {
    pub(super) fn register() -> Signals {
        use signal_hook::consts::{SIGINT, SIGTERM};
        use std::sync::atomic::{AtomicBool, AtomicUsize};
        use std::sync::Arc;
        let flag = Arc::new(AtomicUsize::new(0));
        let again = Arc::new(AtomicBool::new(false));
        let mut ids = Vec::new();
        for (sig, code) in [(SIGINT, 130), (SIGTERM, 143)] {
            // order matters: the shutdown check sees the flag as the previous signal left it
            if let Ok(id) = signal_hook::flag::register_conditional_shutdown(sig, code, again.clone()) {
                ids.push(id);
            }
            if let Ok(id) = signal_hook::flag::register(sig, again.clone()) {
                ids.push(id);
            }
            if let Ok(id) = signal_hook::flag::register_usize(sig, flag.clone(), sig as usize) {
                ids.push(id);
            }
        }
        Signals { flag, ids }
    }

    pub(super) fn caught(&self) -> Option<&'static str> {
        match self.flag.load(std::sync::atomic::Ordering::Relaxed) as i32 {
            0 => None,
            signal_hook::consts::SIGINT => Some("SIGINT"),
            _ => Some("SIGTERM"),
        }
    }
}

impl Drop for Signals {
    fn drop(&mut self) {
        for id in self.ids.drain(..) {
            signal_hook::low_level::unregister(id);
        }
    }
}
