//! Scene edits from the control API, coalesced: for each object only the newest emission is
//! kept, so changes that arrive faster than solves never queue up.

use std::collections::BTreeMap;
use std::sync::{Condvar, Mutex};

/// Pending edits and the signal that wakes the solver thread.
#[derive(Debug, Default)]
pub struct Edits {
    pending: Mutex<Pending>,
    wake: Condvar,
}

#[derive(Debug, Default)]
struct Pending {
    emissions: BTreeMap<String, [f64; 3]>,
    closed: bool,
}

impl Edits {
    /// Records a new emission for `object`, replacing any not yet applied.
    pub fn set_emission(&self, object: &str, emission: [f64; 3]) {
        let mut pending = self.pending.lock().expect("edits lock");
        pending.emissions.insert(object.to_string(), emission);
        self.wake.notify_one();
    }

    /// Waits for edits and takes them all; `None` once closed.
    pub fn wait(&self) -> Option<BTreeMap<String, [f64; 3]>> {
        let mut pending = self.pending.lock().expect("edits lock");
        loop {
            if pending.closed {
                return None;
            }
            if !pending.emissions.is_empty() {
                return Some(std::mem::take(&mut pending.emissions));
            }
            pending = self.wake.wait(pending).expect("edits lock");
        }
    }

    /// Objects with an edit not yet taken by the solver thread.
    pub fn pending(&self) -> usize {
        self.pending.lock().expect("edits lock").emissions.len()
    }

    /// Ends [`Edits::wait`] for good (shutdown).
    pub fn close(&self) {
        self.pending.lock().expect("edits lock").closed = true;
        self.wake.notify_all();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn newest_edit_per_object_wins_and_close_ends_waiting() {
        let edits = Edits::default();
        for level in 0..100 {
            edits.set_emission("light", [level as f64; 3]);
        }
        edits.set_emission("wall", [1.0, 0.0, 0.0]);
        let batch = edits.wait().expect("edits");
        assert_eq!(batch.len(), 2);
        assert_eq!(batch["light"], [99.0; 3]);
        edits.close();
        assert_eq!(edits.wait(), None);
    }
}
