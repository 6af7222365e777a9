//! The running moments a chunk of runs accumulates: one slot's estimates (Welford, merged by
//! Chan, Golub & LeVeque), one residual pair's cross-products, and all of a chunk's.

use estim_core::linalg::inverse_quadratic_form;
use estim_core::nalgebra::SMatrix;
use estim_core::{Error, Quantity};

use crate::consistency::STAGE;
use crate::validation::{Result, ValidationError};

/// Running moments of one slot's estimates, in f64, column-major n × n matrices.
#[derive(Clone, Debug, Default)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub(super) struct SlotAcc {
    pub(super) n: usize,
    pub(super) count: usize,
    pub(super) mean_e: Vec<f64>,
    pub(super) mean_x: Vec<f64>,
    /// Σ (e − ē)(e − ē)ᵀ.
    pub(super) c_ee: Vec<f64>,
    /// Σ (e − ē)(x̂ − x̄)ᵀ.
    pub(super) c_ex: Vec<f64>,
    /// Σ (x̂ᵢ − x̄ᵢ)².
    pub(super) m2_x: Vec<f64>,
    pub(super) sum_p: Vec<f64>,
    pub(super) sum_nees: f64,
    pub(super) nis_count: usize,
    pub(super) nis_dof: usize,
    pub(super) sum_nis: f64,
    pub(super) sum_ll: f64,
}

pub(super) fn mismatch(quantity: Quantity, expected: usize, found: usize) -> ValidationError {
    ValidationError::Estimation(Error::DimensionMismatch {
        stage: STAGE,
        quantity,
        expected_rows: expected,
        expected_cols: 1,
        found_rows: found,
        found_cols: 1,
    })
}

/// An n × n column-major buffer as N columns of N, if it has N² entries.
#[cfg_attr(not(debug_assertions), inline(always))]
fn square<const N: usize>(m: &[f64]) -> Option<&[[f64; N]; N]> {
    let (columns, rest) = m.as_chunks::<N>();
    if rest.is_empty() {
        columns.try_into().ok()
    } else {
        None
    }
}

/// [`square`], mutably.
#[cfg_attr(not(debug_assertions), inline(always))]
fn square_mut<const N: usize>(m: &mut [f64]) -> Option<&mut [[f64; N]; N]> {
    let (columns, rest) = m.as_chunks_mut::<N>();
    if rest.is_empty() {
        columns.try_into().ok()
    } else {
        None
    }
}

/// The NEES eᵀP⁻¹e of a state of n ≤ 6 components by [`inverse_quadratic_form`] on a
/// fixed-size copy of P (the algorithm of the runtime-size path, unrolled): `Some(None)` if P
/// is not positive definite, `None` if n is not small.
pub(super) fn small_nees(p: &[f64], e: &[f64], n: usize) -> Option<Option<f64>> {
    fn fixed<const N: usize>(p: &[f64], e: &[f64]) -> Option<Option<f64>> {
        if p.len() != N * N || e.len() != N {
            return None;
        }
        let mut c = SMatrix::<f64, N, N>::zeros();
        c.as_mut_slice().copy_from_slice(p);
        let mut v = SMatrix::<f64, N, 1>::zeros();
        v.as_mut_slice().copy_from_slice(e);
        // |L⁻¹e|² summed in index order, as the runtime-size dot product does below 8 entries
        // (nalgebra's fixed-size one pairs the terms differently at n = 4).
        Some(inverse_quadratic_form(&mut c, &mut v).map(|_| v.iter().fold(0.0, |s, &x| s + x * x)))
    }
    match n {
        1 => fixed::<1>(p, e),
        2 => fixed::<2>(p, e),
        3 => fixed::<3>(p, e),
        4 => fixed::<4>(p, e),
        5 => fixed::<5>(p, e),
        6 => fixed::<6>(p, e),
        _ => None,
    }
}

impl SlotAcc {
    pub(super) fn ensure_dim(&mut self, n: usize) -> Result<()> {
        if self.count == 0 && self.n == 0 {
            self.n = n;
            self.mean_e = vec![0.0; n];
            self.mean_x = vec![0.0; n];
            self.c_ee = vec![0.0; n * n];
            self.c_ex = vec![0.0; n * n];
            self.m2_x = vec![0.0; n];
            self.sum_p = vec![0.0; n * n];
            Ok(())
        } else if self.n == n {
            Ok(())
        } else {
            Err(mismatch(Quantity::Mean, self.n, n))
        }
    }

    /// Welford: with δ = v − mean_old, mean += δ/k and C += (k − 1)/k δ δᵀ. States of up to
    /// 6 components go through [`add_small`](Self::add_small) (the same operations in
    /// the same order, so the same bits, on fixed-size arrays the compiler unrolls).
    pub(super) fn add(
        &mut self,
        e: &[f64],
        x: &[f64],
        p: &[f64],
        nees: f64,
        de: &mut [f64],
        dx: &mut [f64],
    ) {
        let done = match self.n {
            1 => self.add_small::<1>(e, x, p, nees),
            2 => self.add_small::<2>(e, x, p, nees),
            3 => self.add_small::<3>(e, x, p, nees),
            4 => self.add_small::<4>(e, x, p, nees),
            5 => self.add_small::<5>(e, x, p, nees),
            6 => self.add_small::<6>(e, x, p, nees),
            _ => false,
        };
        if !done {
            self.add_any(e, x, p, nees, de, dx);
        }
    }

    /// [`add_any`](Self::add_any) for n = N; false (nothing changed) if a buffer is not of the
    /// size n says (never, for what this crate builds).
    #[cfg_attr(not(debug_assertions), inline(always))]
    fn add_small<const N: usize>(&mut self, e: &[f64], x: &[f64], p: &[f64], nees: f64) -> bool {
        let (Ok(e), Ok(x)) = (<&[f64; N]>::try_from(e), <&[f64; N]>::try_from(x)) else {
            return false;
        };
        let (Some(p), Some(c_ee), Some(c_ex), Some(sum_p)) = (
            square::<N>(p),
            square_mut::<N>(&mut self.c_ee),
            square_mut::<N>(&mut self.c_ex),
            square_mut::<N>(&mut self.sum_p),
        ) else {
            return false;
        };
        let (Ok(mean_e), Ok(mean_x), Ok(m2_x)) = (
            <&mut [f64; N]>::try_from(self.mean_e.as_mut_slice()),
            <&mut [f64; N]>::try_from(self.mean_x.as_mut_slice()),
            <&mut [f64; N]>::try_from(self.m2_x.as_mut_slice()),
        ) else {
            return false;
        };
        self.count += 1;
        let k = self.count as f64;
        let f = (k - 1.0) / k;
        let (mut de, mut dx) = ([0.0; N], [0.0; N]);
        for i in 0..N {
            de[i] = e[i] - mean_e[i];
            dx[i] = x[i] - mean_x[i];
            mean_e[i] += de[i] / k;
            mean_x[i] += dx[i] / k;
            m2_x[i] += f * (dx[i] * dx[i]);
        }
        for j in 0..N {
            for i in 0..N {
                c_ee[j][i] += f * (de[i] * de[j]);
                c_ex[j][i] += f * (de[i] * dx[j]);
                sum_p[j][i] += p[j][i];
            }
        }
        self.sum_nees += nees;
        true
    }

    /// The Welford update for any n.
    fn add_any(
        &mut self,
        e: &[f64],
        x: &[f64],
        p: &[f64],
        nees: f64,
        de: &mut [f64],
        dx: &mut [f64],
    ) {
        let n = self.n;
        self.count += 1;
        let k = self.count as f64;
        let f = (k - 1.0) / k;
        for i in 0..n {
            de[i] = e[i] - self.mean_e[i];
            dx[i] = x[i] - self.mean_x[i];
            self.mean_e[i] += de[i] / k;
            self.mean_x[i] += dx[i] / k;
            self.m2_x[i] += f * (dx[i] * dx[i]);
        }
        for j in 0..n {
            for i in 0..n {
                self.c_ee[i + j * n] += f * (de[i] * de[j]);
                self.c_ex[i + j * n] += f * (de[i] * dx[j]);
                self.sum_p[i + j * n] += p[i + j * n];
            }
        }
        self.sum_nees += nees;
    }

    /// Chan–Golub–LeVeque merge of `other` into `self`.
    pub(super) fn merge(&mut self, other: &SlotAcc) -> Result<()> {
        self.nis_count += other.nis_count;
        self.nis_dof += other.nis_dof;
        self.sum_nis += other.sum_nis;
        self.sum_ll += other.sum_ll;
        if other.count == 0 {
            return Ok(());
        }
        self.ensure_dim(other.n)?;
        let n = self.n;
        let (na, nb) = (self.count as f64, other.count as f64);
        self.count += other.count;
        let total = self.count as f64;
        let w = nb / total;
        let f = na * nb / total;
        let de: Vec<f64> = (0..n).map(|i| other.mean_e[i] - self.mean_e[i]).collect();
        let dx: Vec<f64> = (0..n).map(|i| other.mean_x[i] - self.mean_x[i]).collect();
        for i in 0..n {
            self.mean_e[i] += de[i] * w;
            self.mean_x[i] += dx[i] * w;
            self.m2_x[i] = self.m2_x[i] + other.m2_x[i] + f * (dx[i] * dx[i]);
        }
        for j in 0..n {
            for i in 0..n {
                let ij = i + j * n;
                self.c_ee[ij] = self.c_ee[ij] + other.c_ee[ij] + f * (de[i] * de[j]);
                self.c_ex[ij] = self.c_ex[ij] + other.c_ex[ij] + f * (de[i] * dx[j]);
                self.sum_p[ij] += other.sum_p[ij];
            }
        }
        self.sum_nees += other.sum_nees;
        Ok(())
    }
}

/// Σ r(a) r(b)ᵀ and the squares for normalising, for one residual pair.
#[derive(Clone, Debug, Default)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub(super) struct PairAcc {
    pub(super) ma: usize,
    pub(super) mb: usize,
    pub(super) count: usize,
    /// Σ r(a) r(b)ᵀ, ma × mb column-major.
    pub(super) sum_ab: Vec<f64>,
    pub(super) sum_a2: Vec<f64>,
    pub(super) sum_b2: Vec<f64>,
}

impl PairAcc {
    fn ensure_dims(&mut self, ma: usize, mb: usize) -> Result<()> {
        if self.count == 0 && self.ma == 0 && self.mb == 0 {
            self.ma = ma;
            self.mb = mb;
            self.sum_ab = vec![0.0; ma * mb];
            self.sum_a2 = vec![0.0; ma];
            self.sum_b2 = vec![0.0; mb];
            Ok(())
        } else if self.ma != ma {
            Err(mismatch(Quantity::Residual, self.ma, ma))
        } else if self.mb != mb {
            Err(mismatch(Quantity::Residual, self.mb, mb))
        } else {
            Ok(())
        }
    }

    pub(super) fn add(&mut self, a: &[f64], b: &[f64]) -> Result<()> {
        self.ensure_dims(a.len(), b.len())?;
        self.count += 1;
        for (i, &ai) in a.iter().enumerate() {
            self.sum_a2[i] += ai * ai;
        }
        for (j, &bj) in b.iter().enumerate() {
            self.sum_b2[j] += bj * bj;
            for (i, &ai) in a.iter().enumerate() {
                self.sum_ab[i + j * self.ma] += ai * bj;
            }
        }
        Ok(())
    }

    pub(super) fn merge(&mut self, other: &PairAcc) -> Result<()> {
        if other.count == 0 {
            return Ok(());
        }
        self.ensure_dims(other.ma, other.mb)?;
        self.count += other.count;
        for (s, o) in self.sum_ab.iter_mut().zip(&other.sum_ab) {
            *s += o;
        }
        for (s, o) in self.sum_a2.iter_mut().zip(&other.sum_a2) {
            *s += o;
        }
        for (s, o) in self.sum_b2.iter_mut().zip(&other.sum_b2) {
            *s += o;
        }
        Ok(())
    }
}

/// Everything accumulated over a set of runs.
#[derive(Clone, Debug)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub(super) struct Accumulator {
    /// How many runs it holds.
    pub(super) runs: usize,
    pub(super) slots: Vec<SlotAcc>,
    pub(super) pairs: Vec<PairAcc>,
}

impl Accumulator {
    pub(super) fn new(slots: usize, pairs: usize) -> Self {
        Self {
            runs: 0,
            slots: vec![SlotAcc::default(); slots],
            pairs: vec![PairAcc::default(); pairs],
        }
    }

    /// Whether it holds `runs` runs and every buffer has the length its dimensions say: true
    /// for what this crate builds, checked for shards read back from a file (which could have
    /// been edited). Every count is then at most `runs` (one record per slot and run), so the
    /// counts of an experiment's chunks add up to at most its runs; the NIS degrees of freedom
    /// have no such bound ([`dof_fit`](Self::dof_fit)).
    pub(super) fn well_formed(&self, runs: usize, slots: usize, pairs: usize) -> bool {
        let slot_ok = |a: &SlotAcc| {
            let (n, nn) = (a.n, a.n.checked_mul(a.n));
            let empty = a.count == 0 && a.n == 0;
            let counts = a.count <= runs && a.nis_count <= runs;
            counts
                && (empty
                    || (nn.is_some()
                        && [&a.mean_e, &a.mean_x, &a.m2_x].iter().all(|v| v.len() == n)
                        && [&a.c_ee, &a.c_ex, &a.sum_p]
                            .iter()
                            .all(|v| Some(v.len()) == nn)))
        };
        let pair_ok = |p: &PairAcc| {
            p.count <= runs
                && Some(p.sum_ab.len()) == p.ma.checked_mul(p.mb)
                && p.sum_a2.len() == p.ma
                && p.sum_b2.len() == p.mb
        };
        self.runs == runs
            && self.slots.len() == slots
            && self.pairs.len() == pairs
            && self.slots.iter().all(slot_ok)
            && self.pairs.iter().all(pair_ok)
    }

    /// Whether the NIS degrees of freedom of `other` can be added to these without overflow
    /// (always, for what this crate records: a sum of measurement sizes over runs).
    pub(super) fn dof_fit(&self, other: &Accumulator) -> bool {
        self.slots
            .iter()
            .zip(&other.slots)
            .all(|(a, b)| a.nis_dof.checked_add(b.nis_dof).is_some())
    }

    pub(super) fn merge(&mut self, other: &Accumulator) -> Result<()> {
        self.runs += other.runs;
        for (s, o) in self.slots.iter_mut().zip(&other.slots) {
            s.merge(o)?;
        }
        for (s, o) in self.pairs.iter_mut().zip(&other.pairs) {
            s.merge(o)?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::consistency::cholesky_quadratic_form;
    use crate::monte_carlo::run_seed;

    /// The fixed-size recording path (n ≤ 6) gives the bits of the runtime-size one: NEES by
    /// the same factorisation, Welford moments by the same operations.
    #[test]
    fn small_states_record_the_bits_of_the_runtime_size_path() {
        // Deterministic pseudo-random entries in (−1, 1) (SplitMix64).
        let mut seed = 0;
        let mut next = || {
            seed += 1;
            (run_seed(11, seed) >> 11) as f64 / (1u64 << 52) as f64 - 1.0
        };
        for n in 1..=6 {
            let (mut small, mut any) = (SlotAcc::default(), SlotAcc::default());
            small.ensure_dim(n).unwrap();
            any.ensure_dim(n).unwrap();
            for _ in 0..5 {
                let e: Vec<f64> = (0..n).map(|_| next()).collect();
                let x: Vec<f64> = (0..n).map(|_| 10.0 * next()).collect();
                // P = A Aᵀ + I, positive definite.
                let a: Vec<f64> = (0..n * n).map(|_| next()).collect();
                let p: Vec<f64> = (0..n * n)
                    .map(|ij| {
                        let (i, j) = (ij % n, ij / n);
                        let aat: f64 = (0..n).map(|k| a[i + k * n] * a[j + k * n]).sum();
                        aat + if i == j { 1.0 } else { 0.0 }
                    })
                    .collect();
                let (mut chol, mut v) = (p.clone(), e.clone());
                let reference = cholesky_quadratic_form(&mut chol, &mut v, n).unwrap();
                let nees = small_nees(&p, &e, n).unwrap().unwrap();
                assert_eq!(nees.to_bits(), reference.to_bits(), "n = {n}");
                let (mut de, mut dx) = (vec![0.0; n], vec![0.0; n]);
                small.add(&e, &x, &p, nees, &mut de, &mut dx);
                any.add_any(&e, &x, &p, nees, &mut de, &mut dx);
            }
            let bits = |a: &SlotAcc| {
                [&a.mean_e, &a.mean_x, &a.c_ee, &a.c_ex, &a.m2_x, &a.sum_p]
                    .iter()
                    .flat_map(|v| v.iter().map(|x| x.to_bits()))
                    .chain([a.sum_nees.to_bits(), a.count as u64])
                    .collect::<Vec<u64>>()
            };
            assert_eq!(bits(&small), bits(&any), "n = {n}");
        }
        // Not positive definite: refused on both paths.
        assert_eq!(
            small_nees(&[1.0, 2.0, 2.0, 1.0], &[1.0, 0.0], 2),
            Some(None)
        );
        assert!(small_nees(&[1.0; 49], &[1.0; 7], 7).is_none());
    }

    #[test]
    fn welford_and_chan_merge_match_two_pass() {
        // 7 samples of a 2-vector with a large offset (cancellation-prone for raw sums).
        let data: Vec<([f64; 2], [f64; 2])> = (0..7)
            .map(|k| {
                let k = k as f64;
                (
                    [0.3 * k - 1.0, (k * 1.7).sin()],
                    [1e8 + k * k, 1e8 - 2.0 * k],
                )
            })
            .collect();
        let p = [1.0, 0.0, 0.0, 1.0];
        let add = |acc: &mut SlotAcc, (e, x): &([f64; 2], [f64; 2])| {
            acc.ensure_dim(2).unwrap();
            acc.add(e, x, &p, 0.0, &mut [0.0; 2], &mut [0.0; 2]);
        };
        let mut a = SlotAcc::default();
        let mut b = SlotAcc::default();
        for d in &data[..3] {
            add(&mut a, d);
        }
        for d in &data[3..] {
            add(&mut b, d);
        }
        a.merge(&b).unwrap();
        let n = data.len() as f64;
        let me: Vec<f64> = (0..2)
            .map(|i| data.iter().map(|d| d.0[i]).sum::<f64>() / n)
            .collect();
        let mx: Vec<f64> = (0..2)
            .map(|i| data.iter().map(|d| d.1[i]).sum::<f64>() / n)
            .collect();
        for i in 0..2 {
            assert!((a.mean_e[i] - me[i]).abs() < 1e-14);
            for j in 0..2 {
                let cee: f64 = data
                    .iter()
                    .map(|d| (d.0[i] - me[i]) * (d.0[j] - me[j]))
                    .sum();
                let cex: f64 = data
                    .iter()
                    .map(|d| (d.0[i] - me[i]) * (d.1[j] - mx[j]))
                    .sum();
                assert!((a.c_ee[i + 2 * j] - cee).abs() < 1e-12 * cee.abs().max(1.0));
                assert!((a.c_ex[i + 2 * j] - cex).abs() < 1e-9 * cex.abs().max(1.0));
            }
            let m2: f64 = data.iter().map(|d| (d.1[i] - mx[i]).powi(2)).sum();
            assert!((a.m2_x[i] - m2).abs() < 1e-9 * m2);
        }
        assert_eq!(a.count, 7);
    }
}
