//! The Hessian cache behind [`AutoDiff`](super::AutoDiff): the filters ask for Hₖ one component
//! at a time, and one set of hyper-dual passes yields all m of them.

use std::sync::{Mutex, TryLockError};

use nalgebra::{Dim, Matrix, RawStorage};

use super::AdReal;

/// An input that can be part of the Hessian cache's key: its numbers, pushed in order.
///
/// The second-order filters call for the m Hessians of f(·, u, Δt) one at a time;
/// [`AutoDiff`](super::AutoDiff) computes them together and reuses them while the state,
/// the step and this key are bit-for-bit the same. Implemented for `()`, `f32`, `f64`,
/// nalgebra matrices and vectors, arrays and pairs and triples of these. A custom input type
/// implements it by pushing every number the transition reads.
///
/// ```
/// use estim_core::autodiff::InputKey;
/// use estim_core::nalgebra::Vector2;
///
/// /// Wheel speeds and a gear.
/// struct Odometry { wheels: Vector2<f64>, gear: u8 }
/// impl InputKey for Odometry {
///     fn push_key(&self, key: &mut Vec<f64>) {
///         self.wheels.push_key(key);
///         key.push(f64::from(self.gear));
///     }
/// }
/// let mut key = Vec::new();
/// Odometry { wheels: Vector2::new(1.0, 2.0), gear: 3 }.push_key(&mut key);
/// assert_eq!(key, [2.0, 1.0, 2.0, 3.0]); // a vector pushes its length first
/// ```
pub trait InputKey {
    /// Appends the input's numbers to `key`.
    fn push_key(&self, key: &mut Vec<f64>);
}

impl InputKey for () {
    fn push_key(&self, _: &mut Vec<f64>) {}
}

impl InputKey for f64 {
    fn push_key(&self, key: &mut Vec<f64>) {
        key.push(*self);
    }
}

impl InputKey for f32 {
    fn push_key(&self, key: &mut Vec<f64>) {
        key.push(f64::from(*self));
    }
}

impl<T: AdReal, R: Dim, C: Dim, S: RawStorage<T, R, C>> InputKey for Matrix<T, R, C, S> {
    fn push_key(&self, key: &mut Vec<f64>) {
        // The shape too: two inputs of different shapes never share a key.
        key.push(self.nrows() as f64);
        key.extend(self.iter().map(|v| v.widen()));
    }
}

impl<X: InputKey, const K: usize> InputKey for [X; K] {
    fn push_key(&self, key: &mut Vec<f64>) {
        self.iter().for_each(|x| x.push_key(key));
    }
}

impl<A: InputKey, B: InputKey> InputKey for (A, B) {
    fn push_key(&self, key: &mut Vec<f64>) {
        self.0.push_key(key);
        self.1.push_key(key);
    }
}

impl<A: InputKey, B: InputKey, C: InputKey> InputKey for (A, B, C) {
    fn push_key(&self, key: &mut Vec<f64>) {
        self.0.push_key(key);
        self.1.push_key(key);
        self.2.push_key(key);
    }
}

/// Which capability the cached Hessians belong to (a model may be all three).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Kind {
    Process,
    Measurement,
    Function,
}

#[derive(Debug, Default)]
struct Entries {
    kind: Option<Kind>,
    key: Vec<f64>,
    probe: Vec<f64>,
    n: usize,
    m: usize,
    /// Hₖ column-major at `k * n * n`.
    values: Vec<f64>,
    nonzero: Vec<bool>,
}

impl Entries {
    fn hit(&self, kind: Kind) -> bool {
        self.kind == Some(kind)
            && self.key.len() == self.probe.len()
            && self
                .key
                .iter()
                .zip(&self.probe)
                .all(|(a, b)| a.to_bits() == b.to_bits())
    }

    /// Computes the m Hessians into `values` (`compute` leaves m n² numbers there, Hₖ
    /// column-major at `k * n * n`, and returns m) and makes the probe the key.
    fn fill(&mut self, kind: Kind, n: usize, compute: impl FnOnce(&mut Vec<f64>) -> usize) {
        let m = compute(&mut self.values);
        let nn = n * n;
        self.values.resize(m * nn, 0.0);
        self.nonzero.clear();
        self.nonzero.extend(
            self.values
                .chunks(nn.max(1))
                .map(|h| h.iter().any(|v| *v != 0.0)),
        );
        self.nonzero.resize(m, false);
        self.kind = Some(kind);
        self.n = n;
        self.m = m;
        core::mem::swap(&mut self.key, &mut self.probe);
    }

    /// Hₖ to `write`; `false` (nothing written) if it is zero or k ≥ m.
    fn serve(&self, k: usize, write: impl FnOnce(&[f64])) -> bool {
        if k >= self.m || !self.nonzero[k] {
            return false;
        }
        let nn = self.n * self.n;
        write(&self.values[k * nn..(k + 1) * nn]);
        true
    }
}

/// The last point's m Hessians, behind a lock so that an [`AutoDiff`](super::AutoDiff) shared
/// between threads stays `Sync`; a thread that finds it busy computes without it.
#[derive(Debug, Default)]
pub(super) struct HessianCache(Mutex<Entries>);

impl HessianCache {
    pub(super) fn clear(&mut self) {
        let entries = self.0.get_mut().unwrap_or_else(|e| e.into_inner());
        entries.kind = None;
    }

    /// Hₖ at the point whose key `fill_key` pushes, computed by `compute` (which writes all m
    /// Hessians into the buffer it is given and returns m) unless cached; `write` receives it
    /// column-major.
    pub(super) fn hessian_into(
        &self,
        kind: Kind,
        fill_key: impl FnOnce(&mut Vec<f64>),
        n: usize,
        compute: impl FnOnce(&mut Vec<f64>) -> usize,
        k: usize,
        write: impl FnOnce(&[f64]),
    ) -> bool {
        let mut guard = match self.0.try_lock() {
            Ok(guard) => guard,
            Err(TryLockError::Poisoned(e)) => e.into_inner(),
            Err(TryLockError::WouldBlock) => {
                let mut local = Entries::default();
                fill_key(&mut local.probe);
                local.fill(kind, n, compute);
                return local.serve(k, write);
            }
        };
        let entries = &mut *guard;
        entries.probe.clear();
        fill_key(&mut entries.probe);
        if !entries.hit(kind) {
            entries.fill(kind, n, compute);
        }
        entries.serve(k, write)
    }
}
