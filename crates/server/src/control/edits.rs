//! Scene edits from the control API, coalesced: for each object only the newest emission is
//! kept, so changes that arrive faster than solves never queue up.

use solver::Motion;
use std::collections::BTreeMap;
use std::sync::{Condvar, Mutex};
use tokio::sync::watch;

/// Pending edits, the signal that wakes the solver thread, and the count of batches it has
/// finished (applied or refused), which anyone may watch.
#[derive(Debug)]
pub struct Edits {
    pending: Mutex<Pending>,
    wake: Condvar,
    finished: watch::Sender<u64>,
}

impl Default for Edits {
    fn default() -> Self {
        Edits {
            pending: Mutex::default(),
            wake: Condvar::default(),
            finished: watch::Sender::new(0),
        }
    }
}

#[derive(Debug, Default)]
struct Pending {
    batch: Batch,
    closed: bool,
}

/// Edits taken together by the solver thread.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Batch {
    /// The newest emission per object.
    pub emissions: BTreeMap<String, [f64; 3]>,
    /// The moves per object in the order they came, translations that follow one another
    /// summed (they compose by adding; a rotation turns about the centre the object has when
    /// it applies, so it stays a step of its own). Moves of different objects commute.
    pub moves: BTreeMap<String, Vec<Motion>>,
}

impl Batch {
    fn is_empty(&self) -> bool {
        self.emissions.is_empty() && self.moves.is_empty()
    }
}

impl Edits {
    /// Records a new emission for `object`, replacing any not yet applied.
    pub fn set_emission(&self, object: &str, emission: [f64; 3]) {
        let mut pending = self.pending.lock().expect("edits lock");
        pending.batch.emissions.insert(object.to_string(), emission);
        self.wake.notify_one();
    }

    /// Queues a move of `object` after any not yet applied.
    pub fn move_object(&self, object: &str, motion: Motion) {
        let mut pending = self.pending.lock().expect("edits lock");
        let moves = pending.batch.moves.entry(object.to_string()).or_default();
        match moves.last_mut() {
            Some(last) if last.is_translation() && motion.is_translation() => {
                (0..3).for_each(|k| last.translate[k] += motion.translate[k]);
            }
            _ => moves.push(motion),
        }
        self.wake.notify_one();
    }

    /// Waits for edits and takes them all; `None` once closed.
    pub fn wait(&self) -> Option<Batch> {
        let mut pending = self.pending.lock().expect("edits lock");
        loop {
            if pending.closed {
                return None;
            }
            if !pending.batch.is_empty() {
                return Some(std::mem::take(&mut pending.batch));
            }
            pending = self.wake.wait(pending).expect("edits lock");
        }
    }

    /// Objects with an edit not yet taken by the solver thread.
    pub fn pending(&self) -> usize {
        let pending = self.pending.lock().expect("edits lock");
        pending.batch.emissions.len() + pending.batch.moves.len()
    }

    /// Counts one batch as finished: its edits were applied or refused, and what came of it
    /// is published.
    pub fn finish_batch(&self) {
        self.finished.send_modify(|n| *n += 1);
    }

    /// Watches the count of finished batches.
    pub fn finished(&self) -> watch::Receiver<u64> {
        self.finished.subscribe()
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
        let shift = |x, y, z| Motion::from(glam::DVec3::new(x, y, z));
        let turn = Motion {
            rotate: Some(solver::Rotation {
                axis: [0.0, 1.0, 0.0],
                degrees: 90.0,
            }),
            ..Motion::default()
        };
        edits.move_object("box", shift(1.0, 2.0, 0.0));
        edits.move_object("box", shift(0.5, 0.0, -1.0));
        edits.move_object("box", turn);
        edits.move_object("box", shift(1.0, 0.0, 0.0));
        let batch = edits.wait().expect("edits");
        assert_eq!(batch.emissions.len(), 2);
        assert_eq!(batch.emissions["light"], [99.0; 3]);
        assert_eq!(
            batch.moves["box"],
            [shift(1.5, 2.0, -1.0), turn, shift(1.0, 0.0, 0.0)]
        );
        assert_eq!(edits.pending(), 0);
        edits.close();
        assert_eq!(edits.wait(), None);
    }
}
