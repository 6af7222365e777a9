//! Fading-memory recursive least squares: γ = 1 is batch weighted least squares, γ < 1 is
//! exponentially weighted batch least squares, and for B = I the gain and covariance reach
//! their steady state (1 − γ) I and (1 − γ) S.

use crate::common;

use common::{gaussian_matrix, random_spd, rng};
use estim_core::nalgebra::{
    DMatrix, DVector, DefaultAllocator, Dim, Dyn, Matrix3, OMatrix, OVector, U1, U2, U3, Vector3,
};
use estim_core::{Alloc, Gaussian, LinearMeasurement, LinearProcess};
use estim_filters::{Estimator, FadingMemoryRls, KalmanFilter, Predict, Update};
use rand::rngs::StdRng;

/// One observation zₖ = Bₖ θ + vₖ, vₖ ~ N(0, Sₖ).
struct Observation<N: Dim, M: Dim>
where
    DefaultAllocator: Alloc<N, M>,
{
    model: LinearMeasurement<f64, N, M>,
    z: OVector<f64, M>,
}

/// Random regressors, noises and readings of a true θ.
fn observations<N: Dim, M: Dim>(
    r: &mut StdRng,
    n: N,
    m: M,
    theta: &OVector<f64, N>,
    count: usize,
) -> Vec<Observation<N, M>>
where
    DefaultAllocator: Alloc<N, M>,
{
    (0..count)
        .map(|_| {
            let b = gaussian_matrix(r, m, n);
            let s = random_spd(r, m, 0.5, 0.1);
            let v = common::sample(r, &OVector::zeros_generic(m, U1), &s);
            let z = &b * theta + v;
            Observation {
                model: LinearMeasurement {
                    observation: b,
                    noise: s,
                },
                z,
            }
        })
        .collect()
}

/// The exponentially weighted batch least-squares solution after the first k observations:
///
/// ```text
/// minimise γᵏ (θ − θ₀)ᵀ P₀⁻¹ (θ − θ₀) + Σⱼ γᵏ⁻ʲ (zⱼ − Bⱼ θ)ᵀ Sⱼ⁻¹ (zⱼ − Bⱼ θ)
/// ⇒ I = γᵏ P₀⁻¹ + Σⱼ γᵏ⁻ʲ Bⱼᵀ Sⱼ⁻¹ Bⱼ,   θ̂ = I⁻¹ (γᵏ P₀⁻¹ θ₀ + Σⱼ γᵏ⁻ʲ Bⱼᵀ Sⱼ⁻¹ zⱼ),  P = I⁻¹
/// ```
///
/// (the prior enters as one more, pseudo-, observation θ₀ = θ + e, e ~ N(0, P₀)), solved from
/// the normal equations with explicit inverses: an independent computation.
fn batch_least_squares<N: Dim, M: Dim>(
    prior: &Gaussian<f64, N>,
    obs: &[Observation<N, M>],
    gamma: f64,
) -> (OVector<f64, N>, OMatrix<f64, N, N>)
where
    DefaultAllocator: Alloc<N, M>,
{
    let k = obs.len();
    let p0_inv = prior.covariance().clone().try_inverse().unwrap();
    let mut info = &p0_inv * gamma.powi(k as i32);
    let mut rhs = &p0_inv * prior.mean() * gamma.powi(k as i32);
    for (j, o) in obs.iter().enumerate() {
        let w = gamma.powi((k - 1 - j) as i32);
        let bt_s_inv =
            o.model.observation.transpose() * o.model.noise.clone().try_inverse().unwrap();
        info += &bt_s_inv * &o.model.observation * w;
        rhs += &bt_s_inv * &o.z * w;
    }
    let p = info.try_inverse().unwrap();
    (&p * rhs, p)
}

/// Feeds the observations one by one and compares with the batch solution after each.
///
/// Tolerance 1e-10: the recursion and the normal equations are algebraically identical and
/// both well conditioned here (S has eigenvalues ≥ 0.1, P₀ ≥ 0.1 I, cond(I) ≲ 10³), so they
/// differ by round-off, ≈ cond · ε · (number of steps) ≲ 10⁻¹¹.
fn check_against_batch<N: Dim, M: Dim>(
    prior: Gaussian<f64, N>,
    obs: &[Observation<N, M>],
    gamma: f64,
) where
    DefaultAllocator: Alloc<N, M>,
{
    let mut rls = FadingMemoryRls::new(prior.clone(), gamma).unwrap();
    for k in 0..obs.len() {
        let report = rls.update(&obs[k].model, &obs[k].z).unwrap();
        assert!(report.applied());
        let (theta, p) = batch_least_squares(&prior, &obs[..=k], gamma);
        common::assert_estimates_close(
            rls.state(),
            rls.covariance(),
            &theta,
            &p,
            1e-10,
            &format!("gamma {gamma}, after {} observations", k + 1),
        );
    }
}

#[test]
fn rls_with_unit_forgetting_equals_batch_weighted_least_squares() {
    let mut r = rng(11);
    let theta = Vector3::new(1.5, -0.7, 2.0);
    let obs = observations(&mut r, U3, U2, &theta, 60);
    let prior = Gaussian::new(
        Vector3::new(0.5, 0.0, 1.0),
        random_spd(&mut r, U3, 2.0, 0.1),
    )
    .unwrap();
    check_against_batch(prior, &obs, 1.0);
}

#[test]
fn rls_with_unit_forgetting_equals_batch_least_squares_dynamic_sizes() {
    let mut r = rng(12);
    let theta = DVector::from_vec(vec![0.3, -1.0, 2.0, 0.7, 0.0]);
    let obs = observations(&mut r, Dyn(5), Dyn(3), &theta, 40);
    let prior = Gaussian::new(DVector::zeros(5), DMatrix::identity(5, 5) * 10.0).unwrap();
    check_against_batch(prior, &obs, 1.0);
}

/// γ < 1 is the exponentially weighted batch problem (information γ P⁻¹ + Bᵀ S⁻¹ B).
#[test]
fn rls_with_forgetting_equals_exponentially_weighted_batch_least_squares() {
    let mut r = rng(13);
    let theta = Vector3::new(-0.4, 1.0, 0.25);
    let obs = observations(&mut r, U3, U2, &theta, 60);
    let prior = Gaussian::new(Vector3::zeros(), random_spd(&mut r, U3, 1.0, 0.5)).unwrap();
    for gamma in [0.98, 0.9, 0.7] {
        check_against_batch(prior.clone(), &obs, gamma);
    }
}

/// With γ = 1, RLS is the Kalman filter of a constant parameter (F = I, Q = 0).
#[test]
fn rls_with_unit_forgetting_equals_kalman_filter_of_a_constant() {
    let mut r = rng(14);
    let theta = Vector3::new(1.0, 2.0, 3.0);
    let obs = observations(&mut r, U3, U2, &theta, 30);
    let prior = Gaussian::new(Vector3::zeros(), Matrix3::identity() * 4.0).unwrap();
    let constant = LinearProcess {
        transition: Matrix3::identity(),
        input: OMatrix::<f64, U3, U1>::zeros(),
        noise: Matrix3::zeros(),
    };
    let mut rls = FadingMemoryRls::new(prior.clone(), 1.0).unwrap();
    let mut kf = KalmanFilter::new(prior);
    for o in &obs {
        kf.predict(&constant, &OVector::<f64, U1>::zeros(), 1.0)
            .unwrap();
        let a = kf.update(&o.model, &o.z).unwrap();
        let b = rls.update(&o.model, &o.z).unwrap();
        // P / 1 and P + 0 are exact, so the same arithmetic follows: bit for bit.
        assert_eq!(a, b);
        common::assert_bitwise_eq(kf.state(), rls.state(), "state");
        common::assert_bitwise_eq(kf.covariance(), rls.covariance(), "covariance");
    }
}

/// For B = I and constant S, Pₖ⁻¹ = γᵏ P₀⁻¹ + (1 − γᵏ)/(1 − γ) S⁻¹ → S⁻¹/(1 − γ), so
/// P → (1 − γ) S and K = (P/γ)(P/γ + S)⁻¹ → (1 − γ) I (see the doc of `FadingMemoryRls`).
/// After 300 steps γᵏ = 0.9³⁰⁰ ≈ 2·10⁻¹⁴, so the limit is reached to round-off; 1e-9 relative
/// leaves four orders of margin for the round-off of 300 contracting recursions.
#[test]
fn rls_with_identity_regressor_reaches_its_steady_state() {
    let gamma = 0.9;
    let mut r = rng(15);
    let s = random_spd(&mut r, U3, 1.0, 0.05);
    let model = LinearMeasurement {
        observation: Matrix3::identity(),
        noise: s,
    };
    let prior = Gaussian::new(Vector3::new(5.0, -5.0, 0.0), Matrix3::identity() * 100.0).unwrap();
    let mut rls = FadingMemoryRls::new(prior.clone(), gamma).unwrap();
    let p0_inv = prior.covariance().try_inverse().unwrap();
    let s_inv = s.try_inverse().unwrap();
    let mut last_gain = Matrix3::zeros();
    for k in 1..=300 {
        let before = rls.clone();
        let z = Vector3::new(1.0, 2.0, 3.0) + gaussian_matrix(&mut r, U3, U1);
        rls.update(&model, &z).unwrap();

        // The gain the covariance implies: K = (P/γ)(P/γ + S)⁻¹.
        let inflated = before.covariance() / gamma;
        let gain = inflated * (inflated + s).try_inverse().unwrap();
        // ... is the gain the estimator applied: θ⁺ − θ = K (z − θ).
        let step = rls.state() - before.state();
        let predicted_step = gain * (z - before.state());
        assert!(
            (step - predicted_step).amax() <= 1e-10 * predicted_step.amax().max(1e-3),
            "step {k}: state change {step} vs K ν {predicted_step}"
        );
        last_gain = gain;

        // Closed form of the information matrix, at every step (relative 1e-9: the
        // explicit inverse of a matrix with condition ≲ 10⁴ (P₀ = 100 I against S) costs
        // ≲ 10⁻¹²).
        let info = p0_inv * gamma.powi(k) + s_inv * ((1.0 - gamma.powi(k)) / (1.0 - gamma));
        let p_closed = info.try_inverse().unwrap();
        assert!(
            (rls.covariance() - p_closed).amax() <= 1e-9 * p_closed.amax(),
            "step {k}: P = {} vs closed form {p_closed}",
            rls.covariance()
        );
    }

    // The gain, also measured from the estimator's behaviour: with innovation eᵢ the state
    // moves by K eᵢ, the i-th column of K.
    let mut measured_gain = Matrix3::zeros();
    for i in 0..3 {
        let mut probe = rls.clone();
        let z = rls.state() + Vector3::ith(i, 1.0);
        probe.update(&model, &z).unwrap();
        measured_gain.set_column(i, &(probe.state() - rls.state()));
    }
    let expected_gain = Matrix3::identity() * (1.0 - gamma);
    assert!(
        (last_gain - expected_gain).amax() <= 1e-9,
        "gain from P: {last_gain}"
    );
    // θ ~ 1–3 here, so the difference of two states loses ≈ 3 ε/(1 − γ) ≈ 10⁻¹⁴ relative to
    // the gain entries; 1e-9 as above.
    assert!(
        (measured_gain - expected_gain).amax() <= 1e-9,
        "gain from the state change: {measured_gain}"
    );
    let expected_p = s * (1.0 - gamma);
    assert!(
        (rls.covariance() - expected_p).amax() <= 1e-9 * expected_p.amax(),
        "P = {} vs (1 − γ) S = {expected_p}",
        rls.covariance()
    );
}

#[test]
fn rls_rejects_forgetting_factors_outside_zero_one() {
    let prior = Gaussian::new(Vector3::zeros(), Matrix3::identity()).unwrap();
    for gamma in [0.0, -0.5, 1.0 + 1e-12, f64::NAN, f64::INFINITY] {
        let err = FadingMemoryRls::new(prior.clone(), gamma).unwrap_err();
        assert!(
            matches!(
                err,
                estim_core::Error::InvalidParameter {
                    parameter: estim_core::Parameter::ForgettingFactor,
                    ..
                }
            ),
            "gamma {gamma}: {err:?}"
        );
    }
    assert_eq!(
        FadingMemoryRls::new(prior.clone(), 1.0)
            .unwrap()
            .forgetting_factor(),
        1.0
    );
}
