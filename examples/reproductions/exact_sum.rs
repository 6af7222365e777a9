//! Sums of `f64` whose result does not depend on the order of the additions: what a
//! hand-looped Monte Carlo's sums over runs go through so that shards of it (summed apart, then
//! merged) give the bits of one process ([`sharding::Session::sums`](crate::sharding::Session::sums)).
//!
//! [`ExactSum`] keeps the exact sum of everything added as a short list of non-overlapping
//! `f64` partials (Shewchuk 1997, "Adaptive precision floating-point arithmetic", grow-expansion
//! by two-sum, as Python's `math.fsum`) and [`value`](ExactSum::value) rounds it once,
//! correctly (round half to even; Python's final step). The rounded value is a function of the
//! exact sum alone, so any order and any split into shards give the same bits, as long as no
//! partial sum overflows (see below: an overflow depends on the order, as in `math.fsum`). A sum whose
//! partials outgrow three is compressed (Shewchuk's Compress, exact), so most sums keep one to
//! three partials, inline; an addition costs a few flops per partial.
//!
//! Non-finite terms (±∞, NaN) are summed apart, as IEEE does (∞ + −∞ = NaN), and win over the
//! finite part. The sum is exact while its partial sums stay below `f64::MAX` in magnitude; a
//! sum that overflows is ±∞ (these examples' sums are far from that).

use serde::{Deserialize, Serialize};

/// The exact sum of the `f64` added to it (module docs).
#[derive(Clone, Debug, Default)]
pub struct ExactSum {
    /// The partials while there are at most [`INLINE`] of them (the first `len`), in the sum
    /// itself: one cache line per sum, no pointer to follow in the hot loop.
    head: [f64; INLINE],
    len: u8,
    /// All the partials once there are more (`head` is then unused); empty otherwise.
    more: Vec<f64>,
    /// The sum of the non-finite terms (0 if none).
    special: f64,
}

/// Partials kept inline ([`ExactSum`]); sums of similar-sized terms need one to three.
const INLINE: usize = 3;

/// Adds `x` to the non-overlapping `partials` (increasing magnitude) by two-sums: the nonzero
/// rounding errors go back to the front of `partials`, in order; returns how many and the
/// running sum left over (to go last), or `Err` with the sum if it overflowed.
#[inline(always)]
fn grow(partials: &mut [f64], mut x: f64) -> Result<(usize, f64), f64> {
    let mut kept = 0;
    for j in 0..partials.len() {
        let mut y = partials[j];
        if x.abs() < y.abs() {
            std::mem::swap(&mut x, &mut y);
        }
        let hi = x + y;
        if !hi.is_finite() {
            return Err(hi);
        }
        let lo = y - (hi - x);
        if lo != 0.0 {
            partials[kept] = lo;
            kept += 1;
        }
        x = hi;
    }
    Ok((kept, x))
}

/// Fast-two-sum (|a| ≥ |b|, or a = 0): s = fl(a + b) and its rounding error, exactly.
#[inline(always)]
fn fast_two_sum(a: f64, b: f64) -> (f64, f64) {
    let s = a + b;
    (s, b - (s - a))
}

/// Shewchuk's Compress (1997, §2.8): the non-overlapping `e` (increasing magnitude) rewritten
/// in place as the shortest-ish nonadjacent expansion of the same exact sum, increasing
/// magnitude, no zeros; returns its length. Grow-expansion alone leaves many small partials
/// (about 5 after 200 squared errors of mixed sizes); compressed, 2 or 3.
fn compress(e: &mut [f64]) -> usize {
    let Some(mut bottom) = e.len().checked_sub(1) else {
        return 0;
    };
    let mut q = e[bottom];
    for i in (0..bottom).rev() {
        let (s, t) = fast_two_sum(q, e[i]);
        if t != 0.0 {
            e[bottom] = s;
            bottom -= 1;
            q = t;
        } else {
            q = s;
        }
    }
    e[bottom] = q;
    let mut top = 0;
    for i in bottom + 1..e.len() {
        let (s, t) = fast_two_sum(e[i], q);
        if t != 0.0 {
            e[top] = t;
            top += 1;
        }
        q = s;
    }
    e[top] = q;
    if q == 0.0 { top } else { top + 1 }
}

impl ExactSum {
    /// The partials: non-overlapping, nonzero, finite, in increasing magnitude; their exact
    /// sum is the finite part of the sum.
    fn partials(&self) -> &[f64] {
        if self.more.is_empty() {
            &self.head[..usize::from(self.len)]
        } else {
            &self.more
        }
    }

    /// Adds `x` exactly.
    #[inline]
    pub fn add(&mut self, x: f64) {
        if !x.is_finite() {
            self.special += x;
            return;
        }
        let grown = if self.more.is_empty() {
            grow(&mut self.head[..usize::from(self.len)], x)
        } else {
            grow(&mut self.more, x)
        };
        let (kept, x) = match grown {
            Ok(k) => k,
            Err(hi) => {
                // Overflow: the sum is beyond f64 (module docs).
                self.special += hi;
                (self.len, self.more) = (0, Vec::new());
                return;
            }
        };
        let last = usize::from(x != 0.0);
        if self.more.is_empty() && kept + last <= INLINE {
            if last == 1 {
                self.head[kept] = x;
            }
            self.len = (kept + last) as u8;
        } else if self.more.is_empty() {
            // A fourth partial (so x ≠ 0): compress the four; `more` if still over.
            let mut four = [self.head[0], self.head[1], self.head[2], x];
            let n = compress(&mut four);
            if n <= INLINE {
                self.head[..n].copy_from_slice(&four[..n]);
                self.len = n as u8;
            } else {
                self.more.extend_from_slice(&four[..n]);
                self.len = 0;
            }
        } else {
            self.more.truncate(kept);
            if last == 1 {
                self.more.push(x);
            }
            let n = compress(&mut self.more);
            self.more.truncate(n);
            if n <= INLINE {
                self.head[..n].copy_from_slice(&self.more);
                self.len = n as u8;
                self.more.clear();
            }
        }
    }

    /// Adds everything `other` holds, exactly.
    pub fn merge(&mut self, other: &ExactSum) {
        for &p in other.partials() {
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
        let p = self.partials();
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
        let mut bits: Vec<u64> = self.partials().iter().map(|p| p.to_bits()).collect();
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
        if !ordered || v.iter().any(|p| !p.is_finite() || *p == 0.0) {
            return None;
        }
        let mut sum = Self {
            special,
            ..Self::default()
        };
        if v.len() <= INLINE {
            sum.head[..v.len()].copy_from_slice(&v);
            sum.len = v.len() as u8;
        } else {
            sum.more = v;
        }
        Some(sum)
    }
}

/// A fixed number of [`ExactSum`]s, one per quantity an experiment sums over its runs.
#[derive(Clone, Debug)]
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
    #[inline]
    pub fn add(&mut self, i: usize, x: f64) {
        self.0[i].add(x);
    }

    /// Adds `xs` to the sums `start..start + xs.len()`.
    ///
    /// # Panics
    /// If they run past [`len`](Self::len).
    #[track_caller]
    #[inline]
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
