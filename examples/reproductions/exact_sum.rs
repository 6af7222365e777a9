//! Sums of `f64` whose result does not depend on the order of the additions: what a
//! hand-looped Monte Carlo's sums over runs go through so that shards of it (summed apart, then
//! merged) give the bits of one process ([`sharding::Session::sums`](crate::sharding::Session::sums)).
//!
//! [`ExactSum`] keeps the exact sum of everything added as a short list of non-overlapping
//! `f64` partials (Shewchuk 1997, "Adaptive precision floating-point arithmetic", grow-expansion
//! by two-sum, as Python's `math.fsum`) and [`value`](ExactSum::value) rounds it once,
//! correctly (round half to even; Python's final step). The rounded value is a function of the
//! exact sum alone, so any order and any split into shards give the same bits. Sums of
//! similar-sized terms need one to three partials; an addition costs a few flops per partial.
//!
//! Non-finite terms (±∞, NaN) are summed apart, as IEEE does (∞ + −∞ = NaN), and win over the
//! finite part. The sum is exact while its partial sums stay below `f64::MAX` in magnitude; a
//! sum that overflows is ±∞ (these examples' sums are far from that).

use serde::{Deserialize, Serialize};

/// The exact sum of the `f64` added to it (module docs).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ExactSum {
    /// Non-overlapping, nonzero, finite, in increasing magnitude; their exact sum is the sum.
    partials: Vec<f64>,
    /// The sum of the non-finite terms (0 if none).
    special: f64,
}

impl ExactSum {
    /// Adds `x` exactly.
    pub fn add(&mut self, mut x: f64) {
        if !x.is_finite() {
            self.special += x;
            return;
        }
        let mut kept = 0;
        for j in 0..self.partials.len() {
            let mut y = self.partials[j];
            if x.abs() < y.abs() {
                std::mem::swap(&mut x, &mut y);
            }
            let hi = x + y;
            if !hi.is_finite() {
                // Overflow: the sum is beyond f64 (module docs).
                self.special += hi;
                self.partials.clear();
                return;
            }
            let lo = y - (hi - x);
            if lo != 0.0 {
                self.partials[kept] = lo;
                kept += 1;
            }
            x = hi;
        }
        self.partials.truncate(kept);
        if x != 0.0 {
            self.partials.push(x);
        }
    }

    /// Adds everything `other` holds, exactly.
    pub fn merge(&mut self, other: &ExactSum) {
        for &p in &other.partials {
            self.add(p);
        }
        if other.special != 0.0 {
            self.add(other.special);
        }
    }

    /// The sum, correctly rounded to the nearest `f64` (ties to even); the non-finite terms'
    /// sum if there were any.
    pub fn value(&self) -> f64 {
        if self.special != 0.0 {
            return self.special;
        }
        let p = &self.partials;
        let Some(mut n) = p.len().checked_sub(1) else {
            return 0.0;
        };
        // From the largest partial down, until the rounding error of the running sum is
        // nonzero: below it, only the sign of the rest can change the rounding (a tie).
        let (mut hi, mut lo) = (p[n], 0.0);
        while n > 0 {
            let x = hi;
            n -= 1;
            let y = p[n];
            hi = x + y;
            lo = y - (hi - x);
            if lo != 0.0 {
                break;
            }
        }
        // hi + lo exactly, lo half an ulp of hi rounded to even, and the rest of the same
        // sign as lo: the exact sum is past the tie, round away.
        if n > 0 && ((lo < 0.0 && p[n - 1] < 0.0) || (lo > 0.0 && p[n - 1] > 0.0)) {
            let y = lo * 2.0;
            let x = hi + y;
            if x - hi == y {
                hi = x;
            }
        }
        hi
    }

    /// Its state as bits: the partials, then the non-finite part if any (a non-finite last
    /// entry, which no partial is).
    fn to_bits(&self) -> Vec<u64> {
        let mut bits: Vec<u64> = self.partials.iter().map(|p| p.to_bits()).collect();
        if self.special != 0.0 {
            bits.push(self.special.to_bits());
        }
        bits
    }

    /// The inverse of [`to_bits`](Self::to_bits), checking what a partial must be.
    fn from_bits(bits: &[u64]) -> Option<Self> {
        let mut v: Vec<f64> = bits.iter().map(|b| f64::from_bits(*b)).collect();
        let special = match v.last() {
            Some(s) if !s.is_finite() => {
                let s = *s;
                v.pop();
                s
            }
            _ => 0.0,
        };
        let ordered = v.windows(2).all(|w| w[0].abs() < w[1].abs());
        (ordered && v.iter().all(|p| p.is_finite() && *p != 0.0)).then_some(Self {
            partials: v,
            special,
        })
    }
}

/// A fixed number of [`ExactSum`]s, one per quantity an experiment sums over its runs.
#[derive(Clone, Debug, PartialEq)]
pub struct ExactSums(Vec<ExactSum>);

impl ExactSums {
    /// `len` empty sums.
    pub fn new(len: usize) -> Self {
        Self(vec![ExactSum::default(); len])
    }

    /// How many sums.
    pub fn len(&self) -> usize {
        self.0.len()
    }

    /// Whether there are none.
    pub fn is_empty(&self) -> bool {
        self.0.is_empty()
    }

    /// Adds `x` to sum `i`.
    ///
    /// # Panics
    /// If `i` ≥ [`len`](Self::len) (the experiment's own layout is wrong).
    #[track_caller]
    pub fn add(&mut self, i: usize, x: f64) {
        self.0[i].add(x);
    }

    /// Adds `xs` to the sums `start..start + xs.len()`.
    ///
    /// # Panics
    /// If they run past [`len`](Self::len).
    #[track_caller]
    pub fn add_slice(&mut self, start: usize, xs: &[f64]) {
        for (s, x) in self.0[start..start + xs.len()].iter_mut().zip(xs) {
            s.add(*x);
        }
    }

    /// Sum `i`, correctly rounded ([`ExactSum::value`]).
    ///
    /// # Panics
    /// If `i` ≥ [`len`](Self::len).
    #[track_caller]
    pub fn value(&self, i: usize) -> f64 {
        self.0[i].value()
    }

    /// Every sum, correctly rounded.
    pub fn values(&self) -> Vec<f64> {
        self.0.iter().map(ExactSum::value).collect()
    }

    /// Adds `other`'s sums to these, exactly; `false` (nothing changed) if the lengths differ.
    pub fn merge(&mut self, other: &ExactSums) -> bool {
        if other.len() != self.len() {
            return false;
        }
        for (s, o) in self.0.iter_mut().zip(&other.0) {
            s.merge(o);
        }
        true
    }

    /// The state of every sum, for a shard file ([`ExactSum`]'s partials as bits).
    pub(crate) fn to_bits(&self) -> Vec<Vec<u64>> {
        self.0.iter().map(ExactSum::to_bits).collect()
    }

    /// The inverse of [`to_bits`](Self::to_bits); `None` for a state no sum can have.
    pub(crate) fn from_bits(bits: &[Vec<u64>]) -> Option<Self> {
        bits.iter()
            .map(|b| ExactSum::from_bits(b))
            .collect::<Option<Vec<_>>>()
            .map(Self)
    }
}

/// The serialised state of an [`ExactSums`] of some runs of a hand-looped experiment, as a
/// shard file holds it.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub(crate) struct SumsState {
    pub(crate) key: String,
    pub(crate) runs: usize,
    pub(crate) first: usize,
    pub(crate) count: usize,
    pub(crate) sums: Vec<Vec<u64>>,
}
