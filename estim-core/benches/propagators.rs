//! Benchmarks of the moment propagators on a 6 → 4 measurement with static sizes.
//!
//! The function is a radar measurement of a target with position p and velocity v,
//! x = [p; v] ∈ ℝ⁶, seen from a sensor at the origin:
//!
//! ```text
//! z = [ r = |p|,  azimuth = atan2(p_y, p_x),  elevation = atan2(p_z, ρ),  ṙ = p·v / r ]
//! ```
//!
//! with ρ = √(p_x² + p_y²). Every component is nonlinear and has an analytic Jacobian and
//! Hessian (ṙ's Hessian is a dense 6 × 6), so the second-order propagators pay a realistic price
//! for their Hessians. The derivatives are checked against finite differences before anything
//! is timed.
//!
//! Besides the estim propagators, the group contains a hand-written fixed-size linearisation
//! (g(μ), J C Jᵀ, C Jᵀ with plain `SMatrix` arithmetic, no estim code) as the baseline that
//! the propagator times are quoted against in `BENCHMARKS.md`. A second group times the model
//! itself (value, Jacobian, Hessians), so the propagator times can be split into model
//! evaluations and propagator work.
//!
//! Run with `cargo bench -p estim-core-benches --bench propagators`.

use std::hint::black_box;
use std::time::Duration;

use criterion::{Criterion, criterion_group, criterion_main};
use estim_core::derivative::check_derivatives;
use estim_core::nalgebra::{SMatrix, SVector, U4, U6};
use estim_core::{
    Differentiable, Linearized, MomentPropagator, Moments, Sampled, SecondOrder,
    SecondOrderGaussian, TwiceDifferentiable, Unscented, VectorFunction,
};

type State = SVector<f64, 6>;
type Meas = SVector<f64, 4>;
type Jacobian = SMatrix<f64, 4, 6>;
type Square6 = SMatrix<f64, 6, 6>;
type Square4 = SMatrix<f64, 4, 4>;
type Cross = SMatrix<f64, 6, 4>;

/// Range, azimuth, elevation and range rate of a target x = [p; v] from a sensor at the origin.
///
/// The computations live in inherent methods returning plain `SMatrix` types so that the
/// hand-written baseline can call them without going through any estim trait.
#[derive(Clone, Copy, Debug)]
struct Radar;

/// The quantities every derivative of [`Radar`] needs.
struct Geometry {
    p: [f64; 3],
    v: [f64; 3],
    /// ρ² = p_x² + p_y².
    rho2: f64,
    /// ρ.
    rho: f64,
    /// r² = |p|².
    r2: f64,
    /// r.
    r: f64,
    /// s = p·v.
    s: f64,
}

impl Geometry {
    fn new(x: &State) -> Self {
        let p = [x[0], x[1], x[2]];
        let v = [x[3], x[4], x[5]];
        let rho2 = p[0] * p[0] + p[1] * p[1];
        let r2 = rho2 + p[2] * p[2];
        Self {
            p,
            v,
            rho2,
            rho: rho2.sqrt(),
            r2,
            r: r2.sqrt(),
            s: p[0] * v[0] + p[1] * v[1] + p[2] * v[2],
        }
    }

    /// ∇r = [p / r; 0].
    fn grad_r(&self) -> State {
        let p = &self.p;
        State::new(p[0] / self.r, p[1] / self.r, p[2] / self.r, 0.0, 0.0, 0.0)
    }

    /// ∇²r = [(I − p pᵀ / r²) / r, 0; 0, 0].
    fn hess_r(&self) -> Square6 {
        let mut h = Square6::zeros();
        for i in 0..3 {
            for j in 0..3 {
                let delta = if i == j { 1.0 } else { 0.0 };
                h[(i, j)] = (delta - self.p[i] * self.p[j] / self.r2) / self.r;
            }
        }
        h
    }

    /// ∇ρ = [p_x / ρ, p_y / ρ, 0, …].
    fn grad_rho(&self) -> State {
        State::new(
            self.p[0] / self.rho,
            self.p[1] / self.rho,
            0.0,
            0.0,
            0.0,
            0.0,
        )
    }

    /// ∇²ρ: (I₂ − q qᵀ / ρ²) / ρ in the (p_x, p_y) block, q = (p_x, p_y).
    fn hess_rho(&self) -> Square6 {
        let mut h = Square6::zeros();
        for i in 0..2 {
            for j in 0..2 {
                let delta = if i == j { 1.0 } else { 0.0 };
                h[(i, j)] = (delta - self.p[i] * self.p[j] / self.rho2) / self.rho;
            }
        }
        h
    }
}

impl Radar {
    fn value(&self, x: &State) -> Meas {
        let g = Geometry::new(x);
        Meas::new(g.r, g.p[1].atan2(g.p[0]), g.p[2].atan2(g.rho), g.s / g.r)
    }

    fn jacobian_at(&self, x: &State) -> Jacobian {
        let g = Geometry::new(x);
        let (p, v) = (&g.p, &g.v);
        let mut j = Jacobian::zeros();
        for i in 0..3 {
            // r = |p|.
            j[(0, i)] = p[i] / g.r;
            // ṙ = s / r: ∂/∂p = v / r − s p / r³, ∂/∂v = p / r.
            j[(3, i)] = v[i] / g.r - g.s * p[i] / (g.r * g.r2);
            j[(3, 3 + i)] = p[i] / g.r;
        }
        // azimuth = atan2(p_y, p_x).
        j[(1, 0)] = -p[1] / g.rho2;
        j[(1, 1)] = p[0] / g.rho2;
        // elevation = atan2(p_z, ρ): ∂/∂p_z = ρ / r², ∂/∂ρ = −p_z / r², ∂ρ/∂p_i = p_i / ρ.
        j[(2, 0)] = -p[2] * p[0] / (g.rho * g.r2);
        j[(2, 1)] = -p[2] * p[1] / (g.rho * g.r2);
        j[(2, 2)] = g.rho / g.r2;
        j
    }

    fn hessian_at(&self, x: &State, k: usize) -> Square6 {
        let g = Geometry::new(x);
        let p = &g.p;
        match k {
            0 => g.hess_r(),
            1 => {
                // azimuth: second derivatives of atan2(p_y, p_x) in the (p_x, p_y) block.
                let rho4 = g.rho2 * g.rho2;
                let mut h = Square6::zeros();
                h[(0, 0)] = 2.0 * p[0] * p[1] / rho4;
                h[(1, 1)] = -h[(0, 0)];
                h[(0, 1)] = (p[1] * p[1] - p[0] * p[0]) / rho4;
                h[(1, 0)] = h[(0, 1)];
                h
            }
            2 => {
                // elevation = f(u, w) = atan2(u, w), u = p_z, w = ρ (u² + w² = r²):
                // H = f_uu ∇u∇uᵀ + f_ww ∇w∇wᵀ + f_uw (∇u∇wᵀ + ∇w∇uᵀ) + f_w ∇²w.
                let (u, w) = (p[2], g.rho);
                let r4 = g.r2 * g.r2;
                let f_uu = -2.0 * u * w / r4;
                let f_uw = (u * u - w * w) / r4;
                let f_w = -u / g.r2;
                let grad_u = State::new(0.0, 0.0, 1.0, 0.0, 0.0, 0.0);
                let grad_w = g.grad_rho();
                let uw = grad_u * grad_w.transpose();
                grad_u * grad_u.transpose() * f_uu - grad_w * grad_w.transpose() * f_uu
                    + (uw + uw.transpose()) * f_uw
                    + g.hess_rho() * f_w
            }
            3 => {
                // ṙ = f(s, r) = s / r: f_rr = 2s / r³, f_sr = −1 / r², f_s = 1 / r,
                // f_r = −s / r², ∇s = [v; p], ∇²s = [0, I; I, 0].
                let grad_r = g.grad_r();
                let grad_s = State::new(g.v[0], g.v[1], g.v[2], p[0], p[1], p[2]);
                let mut hess_s = Square6::zeros();
                for i in 0..3 {
                    hess_s[(i, 3 + i)] = 1.0;
                    hess_s[(3 + i, i)] = 1.0;
                }
                let sr = grad_s * grad_r.transpose();
                grad_r * grad_r.transpose() * (2.0 * g.s / (g.r * g.r2))
                    - (sr + sr.transpose()) / g.r2
                    + hess_s / g.r
                    - g.hess_r() * (g.s / g.r2)
            }
            _ => panic!("Radar has 4 output components, asked for {k}"),
        }
    }
}

impl VectorFunction<f64, U6, U4> for Radar {
    fn eval(&self, x: &State) -> Meas {
        self.value(x)
    }
}

impl Differentiable<f64, U6, U4> for Radar {
    fn jacobian(&self, x: &State) -> Jacobian {
        self.jacobian_at(x)
    }
}

impl TwiceDifferentiable<f64, U6, U4> for Radar {
    fn hessian(&self, x: &State, k: usize) -> Option<Square6> {
        Some(self.hessian_at(x, k))
    }
}

/// The baseline: linearisation at μ written directly with fixed-size nalgebra arithmetic.
///
/// Same arithmetic as estim's `Linearized` (J C once, then (J C) Jᵀ, and C Jᵀ = (J C)ᵀ), but
/// no trait dispatch, `Result`, shape or finiteness checks, or symmetrisation.
#[inline(never)]
fn hand_linearized(f: &Radar, mean: &State, covariance: &Square6) -> (Meas, Square4, Cross) {
    let y = f.value(mean);
    let j = f.jacobian_at(mean);
    let jc = j * covariance;
    (y, jc * j.transpose(), jc.transpose())
}

/// The operating point: a target ≈ 37 m away, 15° up, closing slowly.
fn operating_point() -> (State, Square6) {
    let mean = State::new(30.0, 20.0, 10.0, -2.0, 1.0, 0.5);
    // C = A Aᵀ + D: symmetric positive definite, with every pair of components correlated.
    let a = Square6::from_fn(|i, j| 0.1 * (1.0 + i as f64) * (1.0 + ((i + 2 * j) % 5) as f64));
    let d = Square6::from_diagonal(&State::new(1.0, 1.0, 0.5, 0.1, 0.1, 0.1));
    (mean, a * a.transpose() + d)
}

fn propagators(c: &mut Criterion) {
    let f = Radar;
    let (mean, covariance) = operating_point();
    assert!(
        covariance.cholesky().is_some(),
        "benchmark covariance must be SPD"
    );

    // Time a correct model only.
    let report = check_derivatives(&f, &mean).expect("derivative check runs");
    assert!(report.is_accurate(1e-6), "Radar derivatives: {report}");

    // The baseline must compute what `Linearized` computes.
    let lin: Moments<f64, U6, U4> = Linearized.propagate(&mean, &covariance, &f).unwrap();
    let (y, cov_y, cross) = hand_linearized(&f, &mean, &covariance);
    assert!((lin.mean - y).amax() <= 1e-12 * y.amax());
    assert!((lin.covariance - cov_y).amax() <= 1e-12 * cov_y.amax());
    assert!((lin.cross_covariance - cross).amax() <= 1e-12 * cross.amax());

    let unscented = Unscented::<f64>::default();
    let cubature = Unscented::<f64>::cubature();
    let sampled = Sampled::new(1000, 7).unwrap();

    let mut group = c.benchmark_group("propagate_6x4_static");
    group.bench_function("baseline: hand-written linearisation", |b| {
        b.iter(|| hand_linearized(black_box(&f), black_box(&mean), black_box(&covariance)))
    });
    group.bench_function("Linearized", |b| {
        b.iter(|| {
            let m: Moments<f64, U6, U4> = Linearized
                .propagate(black_box(&mean), black_box(&covariance), black_box(&f))
                .unwrap();
            m
        })
    });
    group.bench_function("SecondOrder", |b| {
        b.iter(|| {
            let m: Moments<f64, U6, U4> = SecondOrder
                .propagate(black_box(&mean), black_box(&covariance), black_box(&f))
                .unwrap();
            m
        })
    });
    group.bench_function("SecondOrderGaussian", |b| {
        b.iter(|| {
            let m: Moments<f64, U6, U4> = SecondOrderGaussian
                .propagate(black_box(&mean), black_box(&covariance), black_box(&f))
                .unwrap();
            m
        })
    });
    group.bench_function("Unscented::default", |b| {
        b.iter(|| {
            let m: Moments<f64, U6, U4> = black_box(&unscented)
                .propagate(black_box(&mean), black_box(&covariance), black_box(&f))
                .unwrap();
            m
        })
    });
    group.bench_function("Unscented::cubature", |b| {
        b.iter(|| {
            let m: Moments<f64, U6, U4> = black_box(&cubature)
                .propagate(black_box(&mean), black_box(&covariance), black_box(&f))
                .unwrap();
            m
        })
    });
    group.bench_function("Sampled (1000 samples)", |b| {
        b.iter(|| {
            let m: Moments<f64, U6, U4> = black_box(&sampled)
                .propagate(black_box(&mean), black_box(&covariance), black_box(&f))
                .unwrap();
            m
        })
    });
    group.finish();

    // The model's own cost and the covariance factorisation, to split the propagator times
    // into model work, factorisation and the rest.
    let mut group = c.benchmark_group("building_blocks_6x4");
    group.bench_function("value", |b| {
        b.iter(|| black_box(&f).value(black_box(&mean)))
    });
    group.bench_function("jacobian", |b| {
        b.iter(|| black_box(&f).jacobian_at(black_box(&mean)))
    });
    group.bench_function("all 4 hessians", |b| {
        b.iter(|| {
            let x = black_box(&mean);
            let fr = black_box(&f);
            [
                fr.hessian_at(x, 0),
                fr.hessian_at(x, 1),
                fr.hessian_at(x, 2),
                fr.hessian_at(x, 3),
            ]
        })
    });
    group.bench_function("psd_factor (6x6)", |b| {
        b.iter(|| {
            estim_core::linalg::psd_factor(black_box(&covariance), estim_core::Stage::Propagation)
                .unwrap()
        })
    });
    group.bench_function("nalgebra cholesky (6x6)", |b| {
        b.iter(|| black_box(covariance).cholesky().unwrap())
    });
    group.finish();
}

fn config() -> Criterion {
    // Modest times: the benchmark machine is a shared, noisy 2-core box.
    Criterion::default()
        .warm_up_time(Duration::from_secs(1))
        .measurement_time(Duration::from_secs(3))
}

criterion_group! {
    name = benches;
    config = config();
    targets = propagators
}
criterion_main!(benches);
