//! What the server knows is wrong with itself, for `/healthz`, `/metrics` and the control API:
//! faults are kept by kind until the same kind of work succeeds again, so an operator (or a
//! load balancer) sees a failed edit or cache write instead of a silent "ok".

use std::collections::BTreeMap;
use std::sync::Mutex;

/// A kind of fault, cleared by the next success of the same kind.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum Fault {
    /// The last batch of edits had one the solver refused (the rest were applied).
    Edit,
    /// The finished solution could not be written to the cache (a restart solves again).
    CacheWrite,
    /// The last solve stopped short of its tolerance (the iteration limit, or a breakdown):
    /// the frames served are not final.
    NotConverged,
    /// The self-check says the answer served is off by more than the warning level, even at
    /// the low end of its interval; cleared by a check that says otherwise.
    Inaccurate,
    /// The solver thread ended: edits can no longer be applied. Never cleared.
    SolverStopped,
    /// NATS could not be reached or refused a write (origin: publishing; edge: reading).
    Nats,
    /// An edge has not heard its origin for [`crate::fanout::SILENT_AFTER`]: it serves the
    /// last solution it got.
    OriginSilent,
    /// An edge's origin reports a fault of its own.
    Origin,
}

impl Fault {
    /// Every kind, in `/metrics` order.
    pub const ALL: [Fault; 8] = [
        Fault::Edit,
        Fault::CacheWrite,
        Fault::NotConverged,
        Fault::Inaccurate,
        Fault::SolverStopped,
        Fault::Nats,
        Fault::OriginSilent,
        Fault::Origin,
    ];

    /// The label used in `/metrics`.
    pub fn label(self) -> &'static str {
        match self {
            Fault::Edit => "edit",
            Fault::CacheWrite => "cache_write",
            Fault::NotConverged => "not_converged",
            Fault::Inaccurate => "inaccurate",
            Fault::SolverStopped => "solver_stopped",
            Fault::Nats => "nats",
            Fault::OriginSilent => "origin_silent",
            Fault::Origin => "origin",
        }
    }
}

/// The server's state as `/healthz` gives it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Status {
    /// Nothing is wrong.
    Ok,
    /// Serving the last good solution, but something failed; the text says what.
    Degraded(String),
    /// Serving the last solution, but it can no longer change; the text says why.
    Down(String),
}

/// Faults now present, each with its newest message, and how often each kind happened.
#[derive(Debug, Default)]
pub struct Health {
    state: Mutex<BTreeMap<Fault, String>>,
    totals: Mutex<BTreeMap<Fault, u64>>,
}

impl Health {
    /// Records a fault of `kind`, replacing the message of the last one. A fault that begins
    /// (none of its kind present) is counted and logged as an error; one that goes on with a
    /// new message is logged as a warning, and with the same message not again.
    pub fn fault(&self, kind: Fault, message: String) {
        let mut state = self.state.lock().expect("health lock");
        match state.get(&kind) {
            None => {
                tracing::error!("{message}");
                *self
                    .totals
                    .lock()
                    .expect("health lock")
                    .entry(kind)
                    .or_insert(0) += 1;
            }
            Some(old) if *old != message => tracing::warn!("{message}"),
            Some(_) => {}
        }
        state.insert(kind, message);
    }

    /// Records that work of `kind` succeeded, clearing its fault (a stopped solver stays stopped).
    pub fn recovered(&self, kind: Fault) {
        if kind != Fault::SolverStopped {
            self.state.lock().expect("health lock").remove(&kind);
        }
    }

    /// Whether a fault of `kind` is present now.
    pub fn has(&self, kind: Fault) -> bool {
        self.state.lock().expect("health lock").contains_key(&kind)
    }

    /// How many faults of `kind` began since start.
    pub fn total(&self, kind: Fault) -> u64 {
        let totals = self.totals.lock().expect("health lock");
        totals.get(&kind).copied().unwrap_or(0)
    }

    /// Down when the solver stopped, degraded when another fault is present, else ok.
    pub fn status(&self) -> Status {
        let state = self.state.lock().expect("health lock");
        if let Some(message) = state.get(&Fault::SolverStopped) {
            return Status::Down(message.clone());
        }
        match state.values().map(String::as_str).collect::<Vec<_>>() {
            faults if faults.is_empty() => Status::Ok,
            faults => Status::Degraded(faults.join("; ")),
        }
    }

    /// `/healthz`'s text: `ok`, `degraded: WHAT` or `down: WHY`.
    pub fn text(&self) -> String {
        match self.status() {
            Status::Ok => "ok".into(),
            Status::Degraded(what) => format!("degraded: {what}"),
            Status::Down(why) => format!("down: {why}"),
        }
    }

    /// Why edits cannot be applied, if the solver stopped.
    pub fn stopped(&self) -> Option<String> {
        match self.status() {
            Status::Down(reason) => Some(reason),
            _ => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn faults_degrade_until_the_same_work_succeeds_and_a_stop_is_final() {
        let health = Health::default();
        assert_eq!(health.status(), Status::Ok);
        health.fault(Fault::Edit, "move of 'box' refused".into());
        health.fault(Fault::CacheWrite, "cache: disk full".into());
        assert_eq!(
            health.status(),
            Status::Degraded("move of 'box' refused; cache: disk full".into())
        );
        health.fault(Fault::Edit, "move of 'box' refused".into());
        assert_eq!(
            health.total(Fault::Edit),
            1,
            "the same fault going on is not a new one"
        );
        health.recovered(Fault::Edit);
        assert_eq!(health.status(), Status::Degraded("cache: disk full".into()));
        assert_eq!(health.total(Fault::Edit), 1);
        health.fault(Fault::SolverStopped, "solver panicked".into());
        health.recovered(Fault::SolverStopped);
        assert_eq!(health.status(), Status::Down("solver panicked".into()));
        assert_eq!(health.stopped().as_deref(), Some("solver panicked"));
    }
}
