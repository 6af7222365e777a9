//! The bounded history: records in time order, each with the filter's snapshot
//! ([`Rollback`](crate::Rollback)), the input and the sensors' health after its event, in a
//! ring whose records are allocated once and recycled.

use std::collections::VecDeque;

use estim_core::Real;

use super::monitor::Health;
use super::outcome::Outcome;

/// What happened at a record's time.
#[derive(Clone, Debug)]
pub(crate) enum Event<U, R> {
    /// The driver's start (the oldest checkpoint until the ring is full).
    Start,
    /// A new input, held from this time on.
    Input(U),
    /// A prediction to this time, nothing else.
    Mark,
    /// A measurement of `sensor`.
    Measurement { sensor: usize, reading: R },
}

/// One event and the driver's state just after it.
#[derive(Clone, Debug)]
pub(crate) struct Record<T: Real, Sn, U, R> {
    pub time: f64,
    pub event: Event<U, R>,
    /// The filter after the event, as its [`Rollback`](crate::Rollback) snapshot.
    pub snapshot: Sn,
    /// The input in force after the event.
    pub input: U,
    pub health: Health<T>,
    /// The decision, for a measurement.
    pub outcome: Option<Outcome<T>>,
}

impl<T: Real, Sn, U, R> Record<T, Sn, U, R> {
    /// Whether a measurement of `sensor` at `time` goes after this record: records are
    /// ordered by time, and measurements at equal times by sensor index (so that the order
    /// does not depend on the order of arrival); two readings of one sensor at one time
    /// ([`DuplicatePolicy::FuseBoth`](super::DuplicatePolicy::FuseBoth)) in arrival order.
    fn precedes(&self, time: f64, sensor: usize) -> bool {
        match self.event {
            Event::Measurement { sensor: s, .. } if self.time == time => s <= sensor,
            _ => self.time <= time,
        }
    }

    /// Whether this is the measurement of `sensor` at `time`.
    pub fn is_measurement(&self, time: f64, sensor: usize) -> bool {
        matches!(self.event, Event::Measurement { sensor: s, .. } if s == sensor && self.time == time)
    }
}

/// The records, oldest first. `ring.len() + pool.len() ≥ capacity + 1` always: the ring
/// holds at most `capacity` records between calls and more while events are processed (one
/// per event; a batch of k measurements takes k, and the pool grows once to the largest batch).
#[derive(Debug)]
pub(crate) struct History<T: Real, Sn, U, R> {
    ring: VecDeque<Record<T, Sn, U, R>>,
    pool: Vec<Record<T, Sn, U, R>>,
    capacity: usize,
}

impl<T: Real, Sn: Clone, U: Clone, R: Clone> History<T, Sn, U, R> {
    /// A history of `capacity` records whose first is `start`.
    pub fn new(start: Record<T, Sn, U, R>, capacity: usize) -> Self {
        let mut ring = VecDeque::with_capacity(capacity + 1);
        let pool = (0..capacity).map(|_| start.clone()).collect();
        ring.push_back(start);
        Self {
            ring,
            pool,
            capacity,
        }
    }
}

impl<T: Real, Sn, U, R> History<T, Sn, U, R> {
    pub fn len(&self) -> usize {
        self.ring.len()
    }

    pub fn get(&self, i: usize) -> &Record<T, Sn, U, R> {
        &self.ring[i]
    }

    pub fn get_mut(&mut self, i: usize) -> &mut Record<T, Sn, U, R> {
        &mut self.ring[i]
    }

    pub fn latest(&self) -> &Record<T, Sn, U, R> {
        &self.ring[self.ring.len() - 1]
    }

    pub fn oldest(&self) -> &Record<T, Sn, U, R> {
        &self.ring[0]
    }

    pub fn iter(&self) -> impl Iterator<Item = &Record<T, Sn, U, R>> {
        self.ring.iter()
    }

    /// Where a measurement of `sensor` at `time` goes: after every record that precedes it.
    /// 0 means before the oldest checkpoint (not insertable).
    pub fn insertion_index(&self, time: f64, sensor: usize) -> usize {
        let mut i = self.ring.len();
        while i > 0 && !self.ring[i - 1].precedes(time, sensor) {
            i -= 1;
        }
        i
    }

    /// Inserts an event at `i` in a recycled record (no allocation while the pool has one; a
    /// batch larger than the spare records clones one more, kept for later calls).
    pub fn insert(&mut self, i: usize, time: f64, event: Event<U, R>)
    where
        Sn: Clone,
        U: Clone,
        R: Clone,
    {
        let mut record = match self.pool.pop() {
            Some(record) => record,
            None => self.ring[0].clone(),
        };
        record.time = time;
        record.event = event;
        record.outcome = None;
        self.ring.insert(i, record);
    }

    /// Removes record `i` (undoing [`insert`](Self::insert)).
    pub fn remove(&mut self, i: usize) {
        if let Some(record) = self.ring.remove(i) {
            self.pool.push(record);
        }
    }

    /// Records enough for a batch of `batch` events on a full ring: `capacity + batch` in all
    /// (allocates only when it grows).
    pub fn reserve(&mut self, batch: usize)
    where
        Sn: Clone,
        U: Clone,
        R: Clone,
    {
        let total = self.capacity + batch;
        while self.ring.len() + self.pool.len() < total {
            let record = self.ring[0].clone();
            self.pool.push(record);
        }
        self.ring.reserve(total.saturating_sub(self.ring.len()));
    }

    /// Drops the oldest records beyond the capacity.
    pub fn trim(&mut self) {
        while self.ring.len() > self.capacity {
            if let Some(record) = self.ring.pop_front() {
                self.pool.push(record);
            }
        }
    }

    /// Every record, in the ring and in the pool (to re-size a sensor's health).
    pub fn all_mut(&mut self) -> impl Iterator<Item = &mut Record<T, Sn, U, R>> {
        self.ring.iter_mut().chain(self.pool.iter_mut())
    }
}
