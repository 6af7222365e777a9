//! The particle filter's chunked loops: the same bits on 1 and 2 rayon threads and on every
//! run (feature `parallel`), and no allocation per step for runtime sizes.

use estim_core::nalgebra::{DMatrix, DVector, Dyn, Matrix1, Matrix2, Matrix4, U1, U2, U4};
use estim_core::nalgebra::{Vector1, Vector2, Vector4};
use estim_core::{Gaussian, LinearMeasurement, LinearProcess, MeasurementModel, ProcessModel};
use estim_filters::particle::{ParticleFilter, ResampleWhen, Resampling};
use estim_filters::{Estimator, Predict, Rollback, Update};

/// The univariate nonstationary growth model (Gordon, Salmond & Smith 1993):
/// x⁺ = x/2 + 25 x/(1 + x²) + 8 cos(1.2 k) + w, Q = 10, with the step k as the input.
struct Growth;

impl ProcessModel<f64, U1> for Growth {
    type Input = f64;
    fn transition(&self, x: &Vector1<f64>, k: &f64, _: f64) -> Vector1<f64> {
        let x = x[0];
        Vector1::new(x / 2.0 + 25.0 * x / (1.0 + x * x) + 8.0 * (1.2 * k).cos())
    }
    fn process_noise(&self, _: &Vector1<f64>, _: &f64, _: f64) -> Matrix1<f64> {
        Matrix1::new(10.0)
    }
}

/// z = x²/20 + v, R = 1.
struct Square;

impl MeasurementModel<f64, U1, U1> for Square {
    fn measure(&self, x: &Vector1<f64>) -> Vector1<f64> {
        Vector1::new(x[0] * x[0] / 20.0)
    }
    fn measurement_noise(&self, _: &Vector1<f64>) -> Matrix1<f64> {
        Matrix1::new(1.0)
    }
}

/// A 2-D constant-velocity target (x, y, vx, vy), white-acceleration noise of intensity 0.1.
struct ConstantVelocity;

impl ProcessModel<f64, U4> for ConstantVelocity {
    type Input = ();
    fn transition(&self, x: &Vector4<f64>, _: &(), dt: f64) -> Vector4<f64> {
        Vector4::new(x[0] + dt * x[2], x[1] + dt * x[3], x[2], x[3])
    }
    fn process_noise(&self, _: &Vector4<f64>, _: &(), dt: f64) -> Matrix4<f64> {
        let (q, d2, d3) = (0.1, dt * dt / 2.0, dt * dt * dt / 3.0);
        Matrix4::new(
            d3, 0.0, d2, 0.0, //
            0.0, d3, 0.0, d2, //
            d2, 0.0, dt, 0.0, //
            0.0, d2, 0.0, dt,
        ) * q
    }
}

/// Range and bearing from the origin, σ = 0.5 and 0.05 rad; the bearing residual wrapped.
struct RangeBearing;

impl MeasurementModel<f64, U4, U2> for RangeBearing {
    fn measure(&self, x: &Vector4<f64>) -> Vector2<f64> {
        Vector2::new(x[0].hypot(x[1]), x[1].atan2(x[0]))
    }
    fn measurement_noise(&self, _: &Vector4<f64>) -> Matrix2<f64> {
        Matrix2::new(0.25, 0.0, 0.0, 0.0025)
    }
    fn residual_into(&self, a: &Vector2<f64>, b: &Vector2<f64>, out: &mut Vector2<f64>) {
        let d = a - b;
        *out = Vector2::new(
            d[0],
            (d[1] + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU) - std::f64::consts::PI,
        );
    }
}

/// Five bootstrap steps and two auxiliary steps of the growth model, then five of the
/// constant-velocity tracker, from seed 9; returns both filters.
fn run(count: usize, scheme: Resampling) -> (ParticleFilter<f64, U1>, ParticleFilter<f64, U4>) {
    let prior = Gaussian::new(Vector1::new(0.1), Matrix1::new(2.0)).unwrap();
    let mut growth = ParticleFilter::new(prior, count, 9)
        .unwrap()
        .with_resampling(scheme)
        .with_trigger(ResampleWhen::EssBelow(0.7))
        .unwrap();
    for (k, z) in [1.2, 0.4, 5.0, 12.1, 3.3].into_iter().enumerate() {
        growth.predict(&Growth, &(k as f64), 1.0).unwrap();
        growth.update(&Square, &Vector1::new(z)).unwrap();
    }
    for z in [7.5, 0.2] {
        growth
            .auxiliary_step(&Growth, &5.0, 1.0, &Square, &Vector1::new(z))
            .unwrap();
    }
    let prior = Gaussian::new(
        Vector4::new(10.0, 5.0, 1.0, 0.0),
        Matrix4::from_diagonal(&Vector4::new(4.0, 4.0, 1.0, 1.0)),
    )
    .unwrap();
    let mut tracker = ParticleFilter::new(prior, count, 9)
        .unwrap()
        .with_resampling(scheme);
    for k in 1..=5 {
        let t = k as f64;
        let (x, y) = (10.0 + t, 5.0 + 0.1 * t);
        tracker.predict(&ConstantVelocity, &(), 1.0).unwrap();
        let z = Vector2::new(x.hypot(y) + 0.3, y.atan2(x) - 0.02);
        tracker.update(&RangeBearing, &z).unwrap();
    }
    (growth, tracker)
}

/// Every bit a step changes: particles, log-weights, moments, the running likelihood.
fn assert_same_bits<N: estim_core::nalgebra::Dim>(
    a: &ParticleFilter<f64, N>,
    b: &ParticleFilter<f64, N>,
    what: &str,
) where
    estim_core::nalgebra::DefaultAllocator: estim_core::Alloc<N>,
{
    let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    assert_eq!(
        bits(a.particles().as_slice()),
        bits(b.particles().as_slice()),
        "{what}: particles"
    );
    assert_eq!(
        bits(a.log_weights()),
        bits(b.log_weights()),
        "{what}: log-weights"
    );
    assert_eq!(
        a.log_likelihood().to_bits(),
        b.log_likelihood().to_bits(),
        "{what}: likelihood"
    );
    // The snapshot holds the moments too (PartialEq is bitwise up to NaN, and none is NaN).
    assert!(a.snapshot() == b.snapshot(), "{what}: snapshot");
}

/// The same seed gives the same bits on 1 and 2 threads and on every run, for every
/// resampling scheme, at a count where the loops run in parallel (≥ `PARALLEL_MIN`) and at
/// one where they do not.
#[cfg(feature = "parallel")]
#[test]
fn one_and_two_threads_give_the_same_bits() {
    use estim_filters::particle::PARALLEL_MIN;
    let pool = |k| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(k)
            .build()
            .unwrap()
    };
    let (one, two) = (pool(1), pool(2));
    // The library runs the chunks on the pool when it has more than one thread and the count
    // is at least PARALLEL_MIN: the first four cases take the parallel path in `two`.
    assert_eq!(two.install(rayon::current_num_threads), 2);
    for (count, scheme) in [
        (2 * PARALLEL_MIN + 77, Resampling::Systematic),
        (PARALLEL_MIN + 1, Resampling::Multinomial),
        (PARALLEL_MIN + 1, Resampling::Stratified),
        (PARALLEL_MIN + 1, Resampling::Residual),
        (300, Resampling::Systematic),
    ] {
        let serial = one.install(|| run(count, scheme));
        let parallel = two.install(|| run(count, scheme));
        let again = two.install(|| run(count, scheme));
        let what = format!("{count} particles, {scheme:?}");
        assert_same_bits(&serial.0, &parallel.0, &what);
        assert_same_bits(&serial.1, &parallel.1, &what);
        assert_same_bits(&parallel.0, &again.0, &what);
        assert_same_bits(&parallel.1, &again.1, &what);
    }
}

/// A proposal for the growth model twice as wide as its prior: x⁺ ~ N(f(x, k), 2Q), so
/// log p − log q does not cancel.
#[cfg(feature = "parallel")]
struct WideGrowth;

#[cfg(feature = "parallel")]
impl estim_filters::particle::Proposal<f64, U1, U1> for WideGrowth {
    type Input = f64;
    fn propose<R: estim_core::rand::Rng + ?Sized>(
        &self,
        x: &Vector1<f64>,
        k: &f64,
        dt: f64,
        _: &Vector1<f64>,
        rng: &mut R,
    ) -> (Vector1<f64>, f64) {
        use estim_core::rand_distr::{Distribution, StandardNormal};
        let e: f64 = StandardNormal.sample(rng);
        let var = 20.0;
        let log_q = -0.5 * e * e - 0.5 * (std::f64::consts::TAU * var).ln();
        (
            Growth.transition(x, k, dt).add_scalar(var.sqrt() * e),
            log_q,
        )
    }
}

/// The guided step runs its proposal pass and its weighing by chunks too: the same seed gives
/// the same bits on 1 and 2 threads, in parallel (≥ `PARALLEL_MIN`) and serially.
#[cfg(feature = "parallel")]
#[test]
fn guided_steps_give_the_same_bits_on_one_and_two_threads() {
    use estim_filters::particle::PARALLEL_MIN;
    let pool = |k| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(k)
            .build()
            .unwrap()
    };
    let (one, two) = (pool(1), pool(2));
    let guided = |count| {
        let prior = Gaussian::new(Vector1::new(0.1), Matrix1::new(2.0)).unwrap();
        let mut pf = ParticleFilter::new(prior, count, 5)
            .unwrap()
            .with_trigger(ResampleWhen::EssBelow(0.7))
            .unwrap();
        for (k, z) in [1.2, 0.4, 5.0, 12.1].into_iter().enumerate() {
            pf.guided_step(
                &Growth,
                &WideGrowth,
                &(k as f64),
                1.0,
                &Square,
                &Vector1::new(z),
            )
            .unwrap();
        }
        pf
    };
    for count in [PARALLEL_MIN + 77, 300] {
        let serial = one.install(|| guided(count));
        let parallel = two.install(|| guided(count));
        assert_same_bits(&serial, &parallel, &format!("guided, {count} particles"));
    }
}

/// Without rayon the run is reproducible too (the chunked sums have a fixed order).
#[test]
fn runs_reproduce_bit_for_bit() {
    let a = run(1500, Resampling::Systematic);
    let b = run(1500, Resampling::Systematic);
    assert_same_bits(&a.0, &b.0, "growth");
    assert_same_bits(&a.1, &b.1, "tracker");
}

/// A failing step in one chunk leaves the filter bit-identical: a model whose transition is
/// NaN past x = 3 fails only for the particles out there.
#[test]
fn an_error_in_one_chunk_leaves_the_filter_unchanged() {
    struct Cliff;
    impl ProcessModel<f64, U1> for Cliff {
        type Input = ();
        fn transition(&self, x: &Vector1<f64>, _: &(), _: f64) -> Vector1<f64> {
            Vector1::new(if x[0] > 3.0 { f64::NAN } else { x[0] })
        }
        fn process_noise(&self, _: &Vector1<f64>, _: &(), _: f64) -> Matrix1<f64> {
            Matrix1::new(0.01)
        }
    }
    let prior = Gaussian::new(Vector1::new(0.0), Matrix1::new(1.0)).unwrap();
    // 5000 draws of N(0, 1): P(no draw above 3) = (1 − 0.00135)^5000 ≈ 0.1 %; seed 4 has some.
    let mut pf = ParticleFilter::new(prior, 5000, 4).unwrap();
    assert!(pf.particles().iter().any(|&x| x > 3.0));
    let before = pf.clone();
    assert!(pf.predict(&Cliff, &(), 1.0).is_err());
    assert_eq!(pf, before);
    assert!(
        pf.auxiliary_step(&Cliff, &(), 1.0, &Square, &Vector1::new(0.0))
            .is_err()
    );
    assert_eq!(pf, before);
}

/// Runtime sizes: after one warm-up step (which sizes the per-chunk scratch and factorises
/// Q and R once), bootstrap and auxiliary steps and a snapshot round trip allocate nothing,
/// for a `Dyn` state with a `Dyn` measurement. 600 particles: two chunks, serial.
#[test]
fn runtime_size_steps_allocate_nothing() {
    use crate::counting::allocations_during;
    let f = DMatrix::from_row_slice(2, 2, &[1.0, 0.1, 0.0, 1.0]);
    let q = DMatrix::from_row_slice(2, 2, &[1e-3, 0.0, 0.0, 1e-2]);
    let process = LinearProcess::without_input(f, q);
    let sensor = LinearMeasurement {
        observation: DMatrix::from_row_slice(1, 2, &[1.0, 0.0]),
        noise: DMatrix::from_element(1, 1, 0.1),
    };
    let prior = Gaussian::new(DVector::from_vec(vec![0.0, 1.0]), DMatrix::identity(2, 2)).unwrap();
    // The auxiliary step's report-into form takes the models as Gaussian-noise particle models.
    use estim_filters::particle::AdditiveGaussian as g;
    for scheme in [Resampling::Systematic, Resampling::Residual] {
        let mut pf: ParticleFilter<f64, Dyn> = ParticleFilter::new(prior.clone(), 600, 3)
            .unwrap()
            .with_resampling(scheme)
            .with_trigger(ResampleWhen::Always)
            .unwrap();
        let mut report = estim_filters::UpdateReport::zeros(Dyn(1));
        let mut snapshot = pf.snapshot();
        let z = DVector::from_element(1, 0.2);
        pf.predict(&process, &(), 1.0).unwrap();
        pf.update_into(&sensor, &z, &mut report).unwrap();
        pf.auxiliary_step_with(&g(&process), &(), 1.0, &g(&sensor), &z, &mut report)
            .unwrap();
        let count = allocations_during(|| {
            for _ in 0..3 {
                pf.predict(&process, &(), 1.0).unwrap();
                pf.update_into(&sensor, &z, &mut report).unwrap();
                pf.auxiliary_step_with(&g(&process), &(), 1.0, &g(&sensor), &z, &mut report)
                    .unwrap();
                pf.snapshot_into(&mut snapshot);
                pf.restore(&snapshot);
            }
        });
        assert_eq!(count, 0, "{scheme:?}");
    }
}

/// The static-size `U2` filter and the `Dyn` one run the same chunked loops: equal moments
/// to round-off across chunk boundaries (1100 particles: three chunks).
#[test]
fn runtime_and_static_sizes_agree_across_chunks() {
    let f = Matrix2::new(1.0, 0.1, 0.0, 1.0);
    let q = Matrix2::new(1e-3, 0.0, 0.0, 1e-2);
    let process = LinearProcess::without_input(f, q);
    let sensor = LinearMeasurement {
        observation: estim_core::nalgebra::Matrix1x2::new(1.0, 0.0),
        noise: Matrix1::new(0.1),
    };
    let dyn_process = LinearProcess::without_input(
        DMatrix::from_column_slice(2, 2, f.as_slice()),
        DMatrix::from_column_slice(2, 2, q.as_slice()),
    );
    let dyn_sensor = LinearMeasurement {
        observation: DMatrix::from_row_slice(1, 2, &[1.0, 0.0]),
        noise: DMatrix::from_element(1, 1, 0.1),
    };
    let prior = Gaussian::new(Vector2::new(0.0, 1.0), Matrix2::identity()).unwrap();
    let mut fixed: ParticleFilter<f64, U2> = ParticleFilter::new(prior.clone(), 1100, 5).unwrap();
    let mut dynamic: ParticleFilter<f64, Dyn> =
        ParticleFilter::new(prior.into_dyn(), 1100, 5).unwrap();
    for z in [0.1, 0.3, 0.2] {
        fixed.predict(&process, &(), 1.0).unwrap();
        fixed.update(&sensor, &Vector1::new(z)).unwrap();
        fixed
            .auxiliary_step(&process, &(), 1.0, &sensor, &Vector1::new(z))
            .unwrap();
        dynamic.predict(&dyn_process, &(), 1.0).unwrap();
        dynamic
            .update(&dyn_sensor, &DVector::from_element(1, z))
            .unwrap();
        dynamic
            .auxiliary_step(
                &dyn_process,
                &(),
                1.0,
                &dyn_sensor,
                &DVector::from_element(1, z),
            )
            .unwrap();
    }
    // The same streams and operations; nalgebra's static and dynamic products may round
    // differently, so equal to 1e-12 of the spread (a few hundred ulps of accumulated sums).
    let spread = fixed.covariance()[(0, 0)].sqrt();
    for i in 0..2 {
        assert!((dynamic.state()[i] - fixed.state()[i]).abs() <= 1e-12 * spread);
    }
}
