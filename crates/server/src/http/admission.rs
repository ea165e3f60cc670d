//! Admission under two caps, a total and a per-address one: one [`Gate`] counts open TCP
//! connections, another counts viewers. A [`Pass`] holds the place and gives it back when
//! dropped, however the connection ends.

use std::collections::HashMap;
use std::net::IpAddr;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};

/// Which cap refused an admission.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Refusal {
    /// The total is at its cap.
    ServerFull,
    /// The address is at its cap.
    AddressFull,
}

/// Places under a total cap and a per-address cap.
#[derive(Debug)]
pub struct Gate {
    max_total: usize,
    max_per_address: usize,
    open: Mutex<Open>,
    refused_full: AtomicU64,
    refused_address: AtomicU64,
}

#[derive(Debug, Default)]
struct Open {
    total: usize,
    per_address: HashMap<IpAddr, usize>,
}

/// A held place; dropping it frees the place.
#[derive(Debug)]
pub struct Pass {
    gate: Arc<Gate>,
    address: IpAddr,
}

impl Gate {
    /// A gate with no place taken.
    pub fn new(max_total: usize, max_per_address: usize) -> Arc<Gate> {
        Arc::new(Gate {
            max_total,
            max_per_address,
            open: Mutex::default(),
            refused_full: AtomicU64::new(0),
            refused_address: AtomicU64::new(0),
        })
    }

    /// Takes a place for `address`, or says (and counts) which cap refused it. The address cap
    /// is checked first, so one address at its cap never reads as a full server.
    pub fn admit(self: &Arc<Self>, address: IpAddr) -> Result<Pass, Refusal> {
        let mut open = self.open.lock().expect("admission lock");
        let from_address = open.per_address.get(&address).copied().unwrap_or(0);
        let refusal = if from_address >= self.max_per_address {
            Some((Refusal::AddressFull, &self.refused_address))
        } else if open.total >= self.max_total {
            Some((Refusal::ServerFull, &self.refused_full))
        } else {
            None
        };
        if let Some((refusal, counter)) = refusal {
            counter.fetch_add(1, Ordering::Relaxed);
            return Err(refusal);
        }
        open.total += 1;
        *open.per_address.entry(address).or_insert(0) += 1;
        Ok(Pass {
            gate: self.clone(),
            address,
        })
    }

    /// Places held now.
    pub fn open(&self) -> usize {
        self.open.lock().expect("admission lock").total
    }

    /// Addresses holding a place now (entries are removed at zero, so this is what it costs).
    pub fn addresses(&self) -> usize {
        self.open.lock().expect("admission lock").per_address.len()
    }

    /// Admissions refused so far at `refusal`'s cap.
    pub fn refused(&self, refusal: Refusal) -> u64 {
        match refusal {
            Refusal::ServerFull => self.refused_full.load(Ordering::Relaxed),
            Refusal::AddressFull => self.refused_address.load(Ordering::Relaxed),
        }
    }
}

impl Drop for Pass {
    fn drop(&mut self) {
        let mut open = self.gate.open.lock().expect("admission lock");
        open.total -= 1;
        if let Some(count) = open.per_address.get_mut(&self.address) {
            *count -= 1;
            if *count == 0 {
                open.per_address.remove(&self.address);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn caps_refuse_with_the_reason_and_places_come_back() {
        let gate = Gate::new(3, 2);
        let (a, b): (IpAddr, IpAddr) = ("10.0.0.1".parse().unwrap(), "10.0.0.2".parse().unwrap());
        let first = [gate.admit(a).unwrap(), gate.admit(a).unwrap()];
        assert_eq!(gate.admit(a).unwrap_err(), Refusal::AddressFull);
        let third = gate.admit(b).unwrap();
        assert_eq!(gate.admit(b).unwrap_err(), Refusal::ServerFull);
        assert_eq!(gate.admit(a).unwrap_err(), Refusal::AddressFull);
        assert_eq!((gate.open(), gate.addresses()), (3, 2));
        assert_eq!(
            (
                gate.refused(Refusal::AddressFull),
                gate.refused(Refusal::ServerFull)
            ),
            (2, 1)
        );
        drop(first);
        drop(third);
        assert_eq!((gate.open(), gate.addresses()), (0, 0));
        assert!(gate.admit(a).is_ok());
    }
}
