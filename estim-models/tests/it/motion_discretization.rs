//! The discretisation of continuous-time noise against independent routes, and the motion
//! models against closed-form trajectories.
//!
//! - Q_d = ∫₀^Δt e^{Fs} G Q_c Gᵀ e^{Fᵀs} ds by composite Simpson (e^{Fs} from its power series
//!   for the nilpotent chains, nalgebra's `exp` of the n × n F·s otherwise), against
//!   [`continuous_white_noise`] and [`van_loan`];
//! - Van Loan against the closed forms (chains K = 1..4, the coordinated turn, Gauss-Markov);
//! - constant velocity / acceleration, the coordinated turns and the unicycle over irregular
//!   steps against the exact trajectory (a line, a parabola, a circle).

use estim_core::nalgebra::{
    DMatrix, Matrix1, Matrix2, Matrix3, Matrix4, SMatrix, SVector, Vector1, Vector2, Vector3,
    Vector4, Vector5,
};
use estim_core::{Error, Parameter, ProcessModel, Quantity, Stage};
use estim_models::motion::{
    ConstantAcceleration, ConstantVelocity, CoordinatedTurn, CoordinatedTurnRate, GaussMarkov,
    Noise, Unicycle, continuous_white_noise, discrete_white_noise, van_loan,
};

/// Composite Simpson's rule of a matrix function over [0, t] with `n` (even) intervals.
fn simpson(t: f64, n: usize, f: impl Fn(f64) -> DMatrix<f64>) -> DMatrix<f64> {
    let h = t / n as f64;
    let mut sum = f(0.0) + f(t);
    for i in 1..n {
        let w = if i % 2 == 1 { 4.0 } else { 2.0 };
        sum += f(i as f64 * h) * w;
    }
    sum * (h / 3.0)
}

/// The chain F (K × K, ones on the superdiagonal) and G = e_K.
fn chain(k: usize) -> (DMatrix<f64>, DMatrix<f64>) {
    let f = DMatrix::from_fn(k, k, |i, j| if j == i + 1 { 1.0 } else { 0.0 });
    let g = DMatrix::from_fn(k, 1, |i, _| if i == k - 1 { 1.0 } else { 0.0 });
    (f, g)
}

/// e^{Fs} = Σ (Fs)^j/j!, exact for a nilpotent F (F^K = 0).
fn nilpotent_exp(f: &DMatrix<f64>, s: f64) -> DMatrix<f64> {
    let k = f.nrows();
    let mut term = DMatrix::identity(k, k);
    let mut sum = term.clone();
    for j in 1..k {
        term = &term * f * (s / j as f64);
        sum += &term;
    }
    sum
}

fn max_abs_diff(a: &DMatrix<f64>, b: &DMatrix<f64>) -> f64 {
    (a - b).amax()
}

macro_rules! chain_q {
    ($k:literal, $dt:expr, $q:expr) => {
        DMatrix::from_column_slice(
            $k,
            $k,
            continuous_white_noise::<f64, $k>($dt, $q)
                .unwrap()
                .as_slice(),
        )
    };
}

/// The closed form of the chains (K = 1..4) against Simpson. The integrand is a polynomial
/// of degree 2(K − 1) ≤ 6 in s with coefficients ≤ q, so its fourth derivative is at most
/// 6·5·4·3·q·Δt² = 360 q Δt², and Simpson's error is ≤ Δt h⁴ · 360 q Δt² / 180; plus the
/// rounding of the sum, ≤ n ε max|integrand| Δt ≲ 10⁻¹². With n = 400 and Δt ≤ 2 the bound
/// is ≤ 2 · (5·10⁻³)⁴ · 360 · 4 · 1.7/180 ≈ 2·10⁻¹⁰ (1.7 = q); each step's own bound is used.
#[test]
fn chain_noise_equals_the_integral() {
    let q = 1.7;
    let n = 400;
    for dt in [1e-3, 0.05, 0.7, 2.0] {
        let h = dt / n as f64;
        let tol = dt * h.powi(4) * 360.0 * q * dt * dt / 180.0 + 1e-12 * q * dt.max(1.0).powi(7);
        for k in 1..=4 {
            let (f, g) = chain(k);
            let integral = simpson(dt, n, |s| {
                let e = nilpotent_exp(&f, s);
                &e * &g * q * g.transpose() * e.transpose()
            });
            let closed = match k {
                1 => chain_q!(1, dt, q),
                2 => chain_q!(2, dt, q),
                3 => chain_q!(3, dt, q),
                _ => chain_q!(4, dt, q),
            };
            let err = max_abs_diff(&integral, &closed);
            assert!(err <= tol, "K = {k}, Δt = {dt}: {err:e} > {tol:e}");
            // Van Loan on the same system.
            let (phi, vl) = van_loan(&f, &g, &DMatrix::from_element(1, 1, q), dt).unwrap();
            // Van Loan's exponential is accurate to ~10 ε ‖M‖-relative (Padé with scaling and
            // squaring); entries here are ≤ q Δt (≥ the others for Δt ≤ 1) or q Δt⁷: 10⁻¹³
            // relative to the largest entry.
            let scale = closed.amax().max(1.0);
            assert!(
                max_abs_diff(&vl, &closed) <= 1e-13 * scale,
                "K = {k}, Δt = {dt}: Van Loan"
            );
            assert!(max_abs_diff(&phi, &nilpotent_exp(&f, dt)) <= 1e-13 * dt.max(1.0).powi(3));
        }
    }
}

/// Van Loan for a system that is not a chain (a damped oscillator driving a Gauss-Markov
/// state) against Simpson with e^{Fs} from nalgebra's exp at each node. The integrand is
/// analytic, its fourth derivative bounded by ‖F‖⁴ ‖G Q_c Gᵀ‖ e^{2‖F‖Δt} · 16 (each side's
/// derivatives, binomially); with ‖F‖ ≤ 2.5, Δt = 0.8, n = 2000 the Simpson bound is
/// 0.8 · (4·10⁻⁴)⁴ · 16 · 2.5⁴ · 1.5 · e⁴ / 180 ≈ 1.2·10⁻¹¹.
#[test]
fn van_loan_equals_the_integral() {
    let f = Matrix3::new(0.0, 1.0, 0.0, -4.0, -0.6, 1.0, 0.0, 0.0, -0.5);
    let g = SMatrix::<f64, 3, 2>::new(0.0, 0.0, 1.0, 0.0, 0.0, 1.0);
    let qc = Matrix2::new(0.7, 0.2, 0.2, 0.8);
    let dt = 0.8;
    let (phi, q) = van_loan(&f, &g, &qc, dt).unwrap();
    let fd = DMatrix::from_column_slice(3, 3, f.as_slice());
    let gqg = DMatrix::from_column_slice(3, 3, (g * qc * g.transpose()).as_slice());
    let integral = simpson(dt, 2000, |s| {
        let e = (&fd * s).exp();
        &e * &gqg * e.transpose()
    });
    let err = max_abs_diff(&DMatrix::from_column_slice(3, 3, q.as_slice()), &integral);
    assert!(err <= 1.2e-11, "{err:e}");
    assert!(((f * dt).exp() - phi).amax() <= 1e-14);
    assert_eq!(q, q.transpose());
}

/// The coordinated turn's closed-form Q and Φ against Van Loan (F: ṗ = v, v̇ = ω J v), at
/// rates on both sides of the series limit and at ω = 0 (where it is the CV model's Q).
/// Both are accurate to ~10⁻¹⁵ relative: 10⁻¹³ of the largest entry.
#[test]
fn coordinated_turn_noise_is_exact() {
    let q = 0.9;
    for (w, dt) in [
        (0.0, 0.5),
        (1e-7, 1.0),
        (0.3, 1.0),
        (0.9, 1.1),
        (2.0, 1.5),
        (-5.0, 0.3),
    ] {
        let ct = CoordinatedTurn {
            rate: w,
            accel_psd: q,
        };
        let f = Matrix4::new(
            0.0, 0.0, 1.0, 0.0, //
            0.0, 0.0, 0.0, 1.0, //
            0.0, 0.0, 0.0, -w, //
            0.0, 0.0, w, 0.0,
        );
        let g = SMatrix::<f64, 4, 2>::new(0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 1.0);
        let (phi, vl) = van_loan(&f, &g, &(Matrix2::identity() * q), dt).unwrap();
        let closed = ct.process_noise(&Vector4::zeros(), &(), dt);
        let scale = closed.amax();
        assert!(
            (closed - vl).amax() <= 1e-13 * scale,
            "ω = {w}: {closed} vs {vl}"
        );
        let jac = estim_core::ProcessJacobian::transition_jacobian(&ct, &Vector4::zeros(), &(), dt);
        assert!((jac - phi).amax() <= 1e-13, "ω = {w}: Φ");
        // The estimated-rate model uses the same block at its ω.
        let ctr = CoordinatedTurnRate {
            accel_psd: q,
            rate_psd: 0.2,
        };
        let q5 = ctr.process_noise(&Vector5::new(0.0, 0.0, 1.0, 1.0, w), &(), dt);
        assert_eq!(q5.fixed_view::<4, 4>(0, 0), closed);
        assert_eq!(q5[(4, 4)], 0.2 * dt);
    }
    // At ω = 0: the CV model (same state order), to rounding.
    let ct = CoordinatedTurn {
        rate: 0.0,
        accel_psd: q,
    };
    let cv = ConstantVelocity::<f64, 2>::new(Noise::Continuous(q));
    let x = Vector4::new(1.0, 2.0, 3.0, 4.0);
    assert!((ct.process_noise(&x, &(), 0.7) - cv.process_noise(&x, &(), 0.7)).amax() <= 1e-16);
    assert!((ct.transition(&x, &(), 0.7) - cv.transition(&x, &(), 0.7)).amax() <= 1e-15);
}

/// Gauss-Markov: Φ = e^{−Δt/τ}, Q = σ²(1 − e^{−2Δt/τ}) is Van Loan's for F = −1/τ,
/// Q_c = 2σ²/τ; 10⁻¹⁴ relative covers both routes' rounding.
#[test]
fn gauss_markov_is_exact() {
    let (tau, var) = (3.0, 0.25);
    let gm = GaussMarkov {
        time_constant: Vector1::new(tau),
        variance: Vector1::new(var),
    };
    let (tau, var): (f64, f64) = (tau, var);
    for dt in [1e-9f64, 0.01, 1.0, 30.0] {
        let (phi, q) = van_loan(
            &Matrix1::new(-1.0 / tau),
            &Matrix1::new(1.0),
            &Matrix1::new(2.0 * var / tau),
            dt,
        )
        .unwrap();
        let x = Vector1::new(1.0f64);
        let phi: f64 = phi[(0, 0)];
        let q: f64 = q[(0, 0)];
        assert!((gm.transition(&x, &(), dt)[0] - phi).abs() <= 1e-15);
        let qm: f64 = gm.process_noise(&x, &(), dt)[(0, 0)];
        assert!((qm - q).abs() <= 1e-14 * qm, "Δt = {dt}: {qm} vs {q}");
    }
}

/// FilterPy's `Q_discrete_white_noise` values (its docstring's closed forms, written out).
#[test]
fn discrete_white_noise_matches_filterpy() {
    let (dt, v) = (0.3, 2.0);
    let q2 = discrete_white_noise::<f64, 2>(dt, v).unwrap();
    let e2 = Matrix2::new(
        0.25 * dt.powi(4),
        0.5 * dt.powi(3),
        0.5 * dt.powi(3),
        dt * dt,
    ) * v;
    let q3 = discrete_white_noise::<f64, 3>(dt, v).unwrap();
    #[rustfmt::skip]
    let e3 = Matrix3::new(
        0.25 * dt.powi(4), 0.5 * dt.powi(3), 0.5 * dt * dt,
        0.5 * dt.powi(3), dt * dt, dt,
        0.5 * dt * dt, dt, 1.0,
    ) * v;
    let q4 = discrete_white_noise::<f64, 4>(dt, v).unwrap();
    #[rustfmt::skip]
    let e4 = Matrix4::new(
        dt.powi(6) / 36.0, dt.powi(5) / 12.0, dt.powi(4) / 6.0, dt.powi(3) / 6.0,
        dt.powi(5) / 12.0, dt.powi(4) / 4.0, dt.powi(3) / 2.0, dt * dt / 2.0,
        dt.powi(4) / 6.0, dt.powi(3) / 2.0, dt * dt, dt,
        dt.powi(3) / 6.0, dt * dt / 2.0, dt, 1.0,
    ) * v;
    // Products of a few powers: a few ulps.
    assert!((q2 - e2).amax() <= 1e-15);
    assert!((q3 - e3).amax() <= 1e-15);
    assert!((q4 - e4).amax() <= 1e-15);
}

#[test]
fn bad_settings_are_typed_errors() {
    let step = Error::InvalidParameter {
        parameter: Parameter::TimeStep,
        value: -1.0,
    };
    assert_eq!(continuous_white_noise::<f64, 2>(-1.0, 1.0), Err(step));
    assert_eq!(discrete_white_noise::<f64, 3>(-1.0, 1.0), Err(step));
    let (stage, quantity) = (Stage::Construction, Quantity::ProcessNoise);
    assert_eq!(
        continuous_white_noise::<f64, 2>(1.0, -1.0),
        Err(Error::NotPositiveSemiDefinite { stage, quantity })
    );
    assert_eq!(
        continuous_white_noise::<f64, 2>(1.0, f64::NAN),
        Err(Error::NonFinite { stage, quantity })
    );
    let f = Matrix2::new(0.0, 1.0, 0.0, f64::INFINITY);
    assert_eq!(
        van_loan(&f, &Vector2::new(0.0, 1.0), &Matrix1::new(1.0), 0.1).map(|_| ()),
        Err(Error::NonFinite {
            stage,
            quantity: Quantity::Jacobian
        })
    );
    assert!(matches!(
        van_loan(
            &Matrix2::<f64>::zeros(),
            &Vector2::new(0.0, 1.0),
            &Matrix1::new(1.0),
            f64::NAN
        ),
        Err(Error::InvalidParameter {
            parameter: Parameter::TimeStep,
            ..
        })
    ));
    // Runtime sizes: G with the wrong row count.
    let f = DMatrix::<f64>::zeros(3, 3);
    let g = DMatrix::<f64>::zeros(2, 1);
    assert!(matches!(
        van_loan(&f, &g, &DMatrix::identity(1, 1), 0.1),
        Err(Error::DimensionMismatch {
            expected_rows: 3,
            found_rows: 2,
            ..
        })
    ));
    // A non-square F, either way: a typed error (it indexed out of bounds).
    for (rows, cols) in [(3, 2), (2, 3)] {
        let f = DMatrix::<f64>::zeros(rows, cols);
        let g = DMatrix::<f64>::zeros(rows, 1);
        assert!(matches!(
            van_loan(&f, &g, &DMatrix::identity(1, 1), 0.1),
            Err(Error::DimensionMismatch {
                quantity: Quantity::Jacobian,
                found_cols,
                ..
            }) if found_cols == cols
        ));
    }
}

/// Irregular steps summing to T.
const STEPS: [f64; 7] = [0.013, 0.4, 0.07, 1.1, 0.25, 0.002, 0.9];

/// The constant-velocity and -acceleration models over irregular steps land on the line and
/// the parabola: each step is exact, so the error is rounding, ≲ 7 steps · ε · |x| ≈ 10⁻¹⁴.
#[test]
fn kinematic_models_follow_their_trajectories() {
    let cv = ConstantVelocity::<f64, 3>::new(Noise::Continuous(1.0));
    let ca = ConstantAcceleration::<f64, 3>::new(Noise::Discrete(1.0));
    let (p0, v0, a0) = (
        Vector3::new(1.0, -2.0, 0.5),
        Vector3::new(0.3, 2.0, -1.0),
        Vector3::new(-0.4, 0.1, 0.2),
    );
    let mut x = SVector::<f64, 6>::zeros();
    x.fixed_rows_mut::<3>(0).copy_from(&p0);
    x.fixed_rows_mut::<3>(3).copy_from(&v0);
    let mut y = SVector::<f64, 9>::zeros();
    y.fixed_rows_mut::<3>(0).copy_from(&p0);
    y.fixed_rows_mut::<3>(3).copy_from(&v0);
    y.fixed_rows_mut::<3>(6).copy_from(&a0);
    let mut t = 0.0;
    for dt in STEPS {
        x = cv.transition(&x, &(), dt);
        y = ca.transition(&y, &(), dt);
        t += dt;
    }
    assert!((x.fixed_rows::<3>(0) - (p0 + v0 * t)).amax() <= 1e-14);
    assert!((y.fixed_rows::<3>(0) - (p0 + v0 * t + a0 * (t * t / 2.0))).amax() <= 1e-14);
    assert!((y.fixed_rows::<3>(3) - (v0 + a0 * t)).amax() <= 1e-14);
}

/// The turns and the unicycle over irregular steps stay on the circle of radius R = v/ω
/// centred at the origin and reach the angle ωT: exact steps, so rounding only (each step
/// rotates by a rounded angle: ≲ 7 · 4ε · R(1 + ωT) ≈ 10⁻¹³ for R = 5, ωT ≈ 1.4).
#[test]
fn turning_models_follow_a_circle() {
    let (radius, w) = (5.0, 0.5);
    let v = radius * w;
    let ct = CoordinatedTurn {
        rate: w,
        accel_psd: 0.0,
    };
    let ctr = CoordinatedTurnRate {
        accel_psd: 0.0,
        rate_psd: 0.0,
    };
    let odometry = Unicycle {
        speed_variance: 0.0,
        rate_variance: 0.0,
    };
    // From (R, 0) moving north (counter-clockwise).
    let mut a = Vector4::new(radius, 0.0, 0.0, v);
    let mut b = Vector5::new(radius, 0.0, 0.0, v, w);
    let mut c = Vector3::new(radius, 0.0, std::f64::consts::FRAC_PI_2);
    let mut t = 0.0;
    for dt in STEPS {
        a = ct.transition(&a, &(), dt);
        b = ctr.transition(&b, &(), dt);
        c = odometry.transition(&c, &Vector2::new(v, w), dt);
        t += dt;
    }
    let angle = w * t;
    let expected = Vector2::new(radius * angle.cos(), radius * angle.sin());
    let velocity = Vector2::new(-v * angle.sin(), v * angle.cos());
    let tol = 1e-13;
    assert!((a.fixed_rows::<2>(0) - expected).amax() <= tol, "{a}");
    assert!((a.fixed_rows::<2>(2) - velocity).amax() <= tol);
    assert!((b.fixed_rows::<2>(0) - expected).amax() <= tol, "{b}");
    assert!((b.fixed_rows::<2>(2) - velocity).amax() <= tol);
    assert_eq!(b[4], w);
    assert!((c.fixed_rows::<2>(0) - expected).amax() <= tol, "{c}");
    assert!((c[2] - (std::f64::consts::FRAC_PI_2 + angle)).abs() <= 1e-15);
}

/// Van Loan at the largest model size here (constant acceleration in 3-D: n = 9, an 18 × 18
/// exponential, static sizes in, static sizes out) and on runtime sizes, against the model's
/// closed-form Φ and Q: to 10⁻¹³ of the largest entry, as for the chains above; the runtime
/// and static results agree to a few ulps.
#[test]
fn van_loan_at_the_model_sizes() {
    use estim_core::ProcessJacobian;
    let q = 0.4;
    let ca = ConstantAcceleration::<f64, 3>::new(Noise::Continuous(q));
    let mut f = SMatrix::<f64, 9, 9>::zeros();
    let mut g = SMatrix::<f64, 9, 3>::zeros();
    for a in 0..3 {
        f[(a, 3 + a)] = 1.0;
        f[(3 + a, 6 + a)] = 1.0;
        g[(6 + a, a)] = 1.0;
    }
    let qc = Matrix3::identity() * q;
    for dt in [0.01, 0.3, 1.7] {
        let x = SVector::<f64, 9>::zeros();
        let (phi, vl) = van_loan(&f, &g, &qc, dt).unwrap();
        let closed = ca.process_noise(&x, &(), dt);
        assert!(
            (vl - closed).amax() <= 1e-13 * closed.amax().max(1.0),
            "Δt = {dt}"
        );
        assert!((phi - ca.transition_jacobian(&x, &(), dt)).amax() <= 1e-13 * dt.max(1.0).powi(2));
        let (phi_d, q_d) = van_loan(
            &DMatrix::from_column_slice(9, 9, f.as_slice()),
            &DMatrix::from_column_slice(9, 3, g.as_slice()),
            &DMatrix::from_column_slice(3, 3, qc.as_slice()),
            dt,
        )
        .unwrap();
        // The same exponential; the final product Φ (e^M)₁₂ goes through nalgebra's static or
        // dynamic kernel, which sum in different orders: a few ulps (n = 9 terms).
        let ulps = |a: &[f64], b: &[f64]| {
            let scale = b.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            a.iter()
                .zip(b)
                .all(|(x, y)| (x - y).abs() <= 9.0 * f64::EPSILON * scale)
        };
        assert!(ulps(phi_d.as_slice(), phi.as_slice()));
        assert!(ulps(q_d.as_slice(), vl.as_slice()));
    }
}

/// A finite F whose F Δt makes nalgebra's `exp` see M⁸ overflow while M⁶ does not (it then
/// squared 2⁶⁴ times: the call never returned). Now a typed error, at once: e^{−FΔt} itself
/// overflows here (Van Loan needs it, although Φ ≈ 0 and Q_d ≈ 1/2 are finite).
#[test]
fn van_loan_refuses_an_overflowing_step_instead_of_hanging() {
    let overflow = Error::NonFinite {
        stage: Stage::Construction,
        quantity: Quantity::ProcessNoise,
    };
    let one = Matrix1::new(1.0f32);
    assert_eq!(
        van_loan(&Matrix1::new(-1.0f32), &one, &one, 1.0e5),
        Err(overflow)
    );
    let one = Matrix1::new(1.0);
    assert_eq!(
        van_loan(&Matrix1::new(1.0e45), &one, &one, 1.0),
        Err(overflow)
    );
    // F Δt itself overflows.
    assert_eq!(
        van_loan(&Matrix1::new(1.0e300), &one, &one, 1.0e10),
        Err(overflow)
    );
}

/// Above ‖M‖₁ = 2⁸ (f32) M is scaled down before nalgebra's `exp` and squared back: a rotation
/// F = [0 ω; −ω 0] with ω Δt = 1000 rad still gives Φ = [cos sin; −sin cos](ω Δt) and, for
/// G = I, Q_c = q I, Q_d = q Δt I. Tolerance: f32 carries a phase error of about ω Δt ε =
/// 1.2·10⁻⁴ (ε = 2⁻²³), amplified 4× by the two squarings (‖M‖₁ ≈ 1000): 10⁻³.
#[test]
fn van_loan_scaled_route_matches_a_large_rotation() {
    let (omega, dt, q) = (1000.0f32, 1.0f32, 0.3f32);
    let f = Matrix2::new(0.0, omega, -omega, 0.0);
    let (phi, qd) = van_loan(&f, &Matrix2::identity(), &(Matrix2::identity() * q), dt).unwrap();
    let a = f64::from(omega * dt);
    let exact = Matrix2::new(a.cos(), a.sin(), -a.sin(), a.cos());
    assert!((phi.cast::<f64>() - exact).amax() < 1e-3, "{phi}");
    let exact_q = Matrix2::<f64>::identity() * f64::from(q * dt);
    assert!(
        (qd.cast::<f64>() - exact_q).amax() < 1e-3 * f64::from(q),
        "{qd}"
    );
}
