//! The finite-difference derivative checker: it passes correct derivatives, and it flags — and
//! points at — a wrong Jacobian entry, a wrong Hessian entry and a nonlinear component whose
//! Hessian is declared `None`; in f64 and f32, for plain functions and for process and
//! measurement models (including wrapped measurement residuals).
//!
//! Tolerance for correct derivatives (f64): the checker steps hⱼ = ε^⅓ max(1, |xⱼ|), at most
//! 1.9·10⁻⁵ for |xⱼ| ≤ 3. A central difference is off by ≤ h²M₃/6 (truncation, M₃ a bound on
//! the third derivative along eⱼ) + εM₀/h (round-off, M₀ a bound on the values). For the test
//! functions below at |x| ≤ 3, M₀, M₃ ≲ 100, so the error is ≲ 6·10⁻⁹ + 4·10⁻⁹ ≈ 10⁻⁸; the
//! documented `is_accurate(1e-6)` leaves a 100× margin, and a wrong entry of size 10⁻³ (or
//! more) is 1000× above it.
//!
//! f32: h = ε₃₂^⅓ max(1, |x|) ≤ 9.8·10⁻³ for |x| ≤ 2, so h²M₃/6 ≲ 1.6·10⁻³ and ε₃₂M₀/h ≲
//! 2.4·10⁻³ with M ≲ 100: `is_accurate(1e-2)` (the documented f32 level) has a ≈ 2.5× margin.

use crate::common;

use common::*;
use estim_core::derivative::{self, DerivativeCheck, Entry};
use estim_core::nalgebra::{
    DefaultAllocator, Dim, Dyn, Matrix2, Matrix3, OMatrix, OVector, U2, U3, U4, U5, Vector2,
    Vector3, Vector5,
};
use estim_core::{
    Alloc, Differentiable, Error, MeasurementHessian, MeasurementJacobian, MeasurementModel,
    Parameter, ProcessHessian, ProcessJacobian, ProcessModel, Quantity, Real, Stage,
    TwiceDifferentiable, VectorFunction,
};
use proptest::prelude::*;

/// f64 tolerance (see the module docs).
const TOL: f64 = 1e-6;
/// f32 tolerance (see the module docs).
const TOL_F32: f32 = 1e-2;

/// g with one entry of its Jacobian and/or Hessian corrupted, or one Hessian declared `None`.
struct Corrupted<G> {
    inner: G,
    jacobian: Option<(usize, usize, f64)>,
    hessian: Option<(usize, usize, usize, f64)>,
    drop_hessian: Option<usize>,
}

impl<G> Corrupted<G> {
    fn new(inner: G) -> Self {
        Self {
            inner,
            jacobian: None,
            hessian: None,
            drop_hessian: None,
        }
    }
}

impl<T: Real, N: Dim, M: Dim, G: VectorFunction<T, N, M>> VectorFunction<T, N, M> for Corrupted<G>
where
    DefaultAllocator: Alloc<N, M>,
{
    fn eval(&self, x: &OVector<T, N>) -> OVector<T, M> {
        self.inner.eval(x)
    }
}

impl<T: Real, N: Dim, M: Dim, G: Differentiable<T, N, M>> Differentiable<T, N, M> for Corrupted<G>
where
    DefaultAllocator: Alloc<N, M>,
{
    fn jacobian(&self, x: &OVector<T, N>) -> OMatrix<T, M, N> {
        let mut j = self.inner.jacobian(x);
        if let Some((r, c, delta)) = self.jacobian {
            j[(r, c)] += estim_core::scalar::real::<T>(delta);
        }
        j
    }
}

impl<T: Real, N: Dim, M: Dim, G: TwiceDifferentiable<T, N, M>> TwiceDifferentiable<T, N, M>
    for Corrupted<G>
where
    DefaultAllocator: Alloc<N, M>,
{
    fn hessian(&self, x: &OVector<T, N>, k: usize) -> Option<OMatrix<T, N, N>> {
        if self.drop_hessian == Some(k) {
            return None;
        }
        let mut h = self.inner.hessian(x, k);
        if let (Some((comp, r, c, delta)), Some(h)) = (self.hessian, h.as_mut())
            && comp == k
        {
            h[(r, c)] += estim_core::scalar::real::<T>(delta);
        }
        h
    }
}

fn assert_accurate<T: Real + std::fmt::Display>(
    what: &str,
    report: derivative::DerivativeReport<T>,
    tol: T,
) {
    assert!(report.entries > 0, "{what}: nothing compared");
    if std::env::var_os("ESTIM_TEST_RATIOS").is_some() {
        eprintln!("ratio {} {what}", report.max_mixed_error() / tol);
    }
    assert!(report.is_accurate(tol), "{what}: {report}");
}

fn point(n: usize, range: f64) -> impl Strategy<Value = Vec<f64>> {
    prop::collection::vec(-range..range, n)
}

proptest! {
    #![proptest_config(config(64, 0x55))]

    #[test]
    fn correct_derivatives_pass(x3 in point(3, 3.0), x4 in point(4, 3.0), x5 in point(5, 3.0), p in prop::collection::vec(-1.0..1.0f64, TrigSum::<f64, U4, U3>::random_len(4, 3)), q in prop::collection::vec(-1.0..1.0f64, 2 * 9 + 6 + 2)) {
        let products = TrigSum::products(U3, U3);
        let x = vector(U3, &x3);
        assert_accurate("products", derivative::check_derivatives(&products, &x).unwrap(), TOL);
        // The same through check_jacobian alone.
        assert_accurate("products J", derivative::check_jacobian(&products, &x).unwrap(), TOL);

        let random = TrigSum::random(U4, U3, &p);
        assert_accurate("random sum", derivative::check_derivatives(&random, &vector(U4, &x4)).unwrap(), TOL);

        let quad = Quadratic {
            q: vec![{ let r = mat(U3, U3, &q[..9]); (r + r.transpose()) * 0.5 }, { let r = mat(U3, U3, &q[9..18]); (r + r.transpose()) * 0.5 }],
            a: mat(U2, U3, &q[18..24]),
            c: vector(U2, &q[24..26]),
        };
        assert_accurate("quadratic", derivative::check_derivatives(&quad, &x).unwrap(), TOL);

        let affine = AffineMap { a: mat(U2, U3, &q[..6]), b: vector(U2, &q[6..8]) };
        assert_accurate("affine", derivative::check_derivatives(&affine, &x).unwrap(), TOL);

        let boje = Boje { r: 0.5 };
        assert_accurate("Boje eq 5", derivative::check_derivatives(&boje, &vector(U5, &x5)).unwrap(), TOL);

        let dynamic = TrigSum::products(Dyn(3), Dyn(3));
        assert_accurate("products (dynamic)", derivative::check_derivatives(&dynamic, &vector(Dyn(3), &x3)).unwrap(), TOL);
    }

    /// A Jacobian entry off by δ ≥ 10⁻³ is flagged, and the report names that entry.
    #[test]
    fn wrong_jacobian_entry_is_flagged(x3 in point(3, 3.0), row in 0usize..3, col in 0usize..3, delta in prop_oneof![1e-3..1.0f64, -1.0..-1e-3f64]) {
        let mut g = Corrupted::new(TrigSum::products(U3, U3));
        g.jacobian = Some((row, col, delta));
        let report = derivative::check_derivatives(&g, &vector(U3, &x3)).unwrap();
        prop_assert!(!report.is_accurate(TOL), "{report}");
        prop_assert_eq!(report.worst_mixed.unwrap().entry, Entry::Jacobian { row, col });
        prop_assert_eq!(report.worst_abs.unwrap().entry, Entry::Jacobian { row, col });
        let c = report.worst_abs.unwrap();
        prop_assert!((c.analytic - c.numeric - delta).abs() <= 1e-7, "the reported discrepancy is δ");
    }

    /// A Hessian entry off by δ (only (i, j), not (j, i)) is flagged and named.
    #[test]
    fn wrong_hessian_entry_is_flagged(x4 in point(4, 3.0), p in prop::collection::vec(-1.0..1.0f64, TrigSum::<f64, U4, U3>::random_len(4, 3)), comp in 0usize..3, i in 0usize..4, j in 0usize..4, delta in prop_oneof![1e-3..1.0f64, -1.0..-1e-3f64]) {
        let mut g = Corrupted::new(TrigSum::random(U4, U3, &p));
        g.hessian = Some((comp, i, j, delta));
        let report = derivative::check_derivatives(&g, &vector(U4, &x4)).unwrap();
        prop_assert!(!report.is_accurate(TOL), "{report}");
        let expected = Entry::Hessian { component: comp, row: i, col: j };
        prop_assert_eq!(report.worst_mixed.unwrap().entry, expected);
        prop_assert_eq!(report.worst_abs.unwrap().entry, expected);
    }
}

/// `None` declares a component affine; for a nonlinear component that is a wrong (zero)
/// Hessian, and the check flags it in that component — at its largest Hessian entry.
#[test]
fn none_hessian_on_nonlinear_component_is_flagged() {
    let products = TrigSum::products(U3, U3);
    for (x, k) in [
        (Vector3::new(0.3, 1.1, -0.4), 0),
        (Vector3::new(-1.0, 0.2, 2.0), 1),
        (Vector3::new(2.0, -0.7, 1.5), 2),
    ] {
        let mut g = Corrupted::new(products.clone());
        g.drop_hessian = Some(k);
        let report = derivative::check_derivatives(&g, &x).unwrap();
        assert!(!report.is_accurate(TOL), "{report}");
        let worst = report.worst_abs.unwrap();
        let Entry::Hessian {
            component,
            row,
            col,
        } = worst.entry
        else {
            panic!("worst entry is not a Hessian entry: {report}");
        };
        assert_eq!(component, k);
        assert_eq!(worst.analytic, 0.0);
        let h = products.hessian(&x, k).unwrap();
        assert_eq!(
            h[(row, col)].abs(),
            h.amax(),
            "the largest missing entry is reported"
        );
    }
    // A truly affine component declared None passes (g₂'s ½x₀ term alone).
    let affine_part = TrigSum {
        m: U3,
        outputs: vec![vec![], vec![], products.outputs[2][1..].to_vec()],
    };
    assert!(
        affine_part
            .hessian(&Vector3::new(1.0, 2.0, 3.0), 2)
            .is_none()
    );
    assert_accurate(
        "affine None",
        derivative::check_derivatives(&affine_part, &Vector3::new(1.0, 2.0, 3.0)).unwrap(),
        TOL,
    );
}

proptest! {
    #![proptest_config(config(64, 0x56))]

    /// f32: correct derivatives pass at the f32 level, a wrong entry of 0.1 is flagged.
    #[test]
    fn f32_checks(x3 in point(3, 2.0), x5 in point(5, 2.0), row in 0usize..3, col in 0usize..3) {
        let products = TrigSum::products(U3, U3).to_f32();
        let x = Vector3::from_iterator(x3.iter().map(|v| *v as f32));
        assert_accurate("f32 products", derivative::check_derivatives(&products, &x).unwrap(), TOL_F32);
        let boje = Boje { r: 0.5f32 };
        let x5 = Vector5::from_iterator(x5.iter().map(|v| *v as f32));
        assert_accurate("f32 Boje", derivative::check_derivatives(&boje, &x5).unwrap(), TOL_F32);

        let mut g = Corrupted::new(products.clone());
        g.jacobian = Some((row, col, 0.1));
        let report = derivative::check_jacobian(&g, &x).unwrap();
        prop_assert!(!report.is_accurate(TOL_F32));
        prop_assert_eq!(report.worst_mixed.unwrap().entry, Entry::Jacobian { row, col });

        let mut g = Corrupted::new(products);
        g.hessian = Some((1, col, row, 0.1));
        let report = derivative::check_derivatives(&g, &x).unwrap();
        prop_assert!(!report.is_accurate(TOL_F32));
        prop_assert_eq!(report.worst_mixed.unwrap().entry, Entry::Hessian { component: 1, row: col, col: row });
    }
}

/// A unicycle x = (px, py, heading, speed) with input (turn rate, acceleration):
/// x⁺ = (px + Δt v cos ψ, py + Δt v sin ψ, ψ + Δt ω, v + Δt a).
struct Unicycle {
    wrong_jacobian: bool,
}

impl ProcessModel<f64, U4> for Unicycle {
    type Input = Vector2<f64>;

    fn transition(&self, x: &OVector<f64, U4>, u: &Vector2<f64>, dt: f64) -> OVector<f64, U4> {
        let (s, c) = x[2].sin_cos();
        OVector::<f64, U4>::new(
            x[0] + dt * x[3] * c,
            x[1] + dt * x[3] * s,
            x[2] + dt * u[0],
            x[3] + dt * u[1],
        )
    }

    fn process_noise(
        &self,
        _: &OVector<f64, U4>,
        _: &Vector2<f64>,
        dt: f64,
    ) -> OMatrix<f64, U4, U4> {
        OMatrix::<f64, U4, U4>::identity() * dt
    }
}

impl ProcessJacobian<f64, U4> for Unicycle {
    fn transition_jacobian(
        &self,
        x: &OVector<f64, U4>,
        _: &Vector2<f64>,
        dt: f64,
    ) -> OMatrix<f64, U4, U4> {
        let (s, c) = x[2].sin_cos();
        let mut f = OMatrix::<f64, U4, U4>::identity();
        f[(0, 2)] = -dt * x[3] * s;
        f[(0, 3)] = dt * c;
        f[(1, 2)] = dt * x[3] * c;
        // A classic slip: the sign of ∂py/∂v.
        f[(1, 3)] = if self.wrong_jacobian { -dt * s } else { dt * s };
        f
    }
}

impl ProcessHessian<f64, U4> for Unicycle {
    fn transition_hessian(
        &self,
        x: &OVector<f64, U4>,
        _: &Vector2<f64>,
        dt: f64,
        k: usize,
    ) -> Option<OMatrix<f64, U4, U4>> {
        let (s, c) = x[2].sin_cos();
        let mut h = OMatrix::<f64, U4, U4>::zeros();
        match k {
            0 => {
                h[(2, 2)] = -dt * x[3] * c;
                h[(2, 3)] = -dt * s;
                h[(3, 2)] = -dt * s;
            }
            1 => {
                h[(2, 2)] = -dt * x[3] * s;
                h[(2, 3)] = dt * c;
                h[(3, 2)] = dt * c;
            }
            _ => return None,
        }
        Some(h)
    }
}

/// Range and bearing from the origin to (px, py): z = (√(px² + py²), atan2(py, px)), with
/// the bearing residual wrapped into (−π, π] unless `plain_residual`.
struct RangeBearing {
    plain_residual: bool,
}

fn wrap(a: f64) -> f64 {
    estim_core::wrap_angle(a)
}

impl MeasurementModel<f64, U4, U2> for RangeBearing {
    fn measure(&self, x: &OVector<f64, U4>) -> Vector2<f64> {
        Vector2::new(x[0].hypot(x[1]), x[1].atan2(x[0]))
    }

    fn measurement_noise(&self, _: &OVector<f64, U4>) -> Matrix2<f64> {
        Matrix2::identity()
    }

    fn residual_into(&self, a: &Vector2<f64>, b: &Vector2<f64>, out: &mut Vector2<f64>) {
        *out = if self.plain_residual {
            a - b
        } else {
            Vector2::new(a[0] - b[0], wrap(a[1] - b[1]))
        };
    }
}

impl MeasurementJacobian<f64, U4, U2> for RangeBearing {
    fn measurement_jacobian(&self, x: &OVector<f64, U4>) -> OMatrix<f64, U2, U4> {
        let r2 = x[0] * x[0] + x[1] * x[1];
        let r = r2.sqrt();
        OMatrix::<f64, U2, U4>::new(
            x[0] / r,
            x[1] / r,
            0.0,
            0.0,
            -x[1] / r2,
            x[0] / r2,
            0.0,
            0.0,
        )
    }
}

impl MeasurementHessian<f64, U4, U2> for RangeBearing {
    fn measurement_hessian(&self, x: &OVector<f64, U4>, k: usize) -> Option<OMatrix<f64, U4, U4>> {
        let (px, py) = (x[0], x[1]);
        let r2 = px * px + py * py;
        let mut h = OMatrix::<f64, U4, U4>::zeros();
        let block = if k == 0 {
            let r3 = r2 * r2.sqrt();
            Matrix2::new(py * py / r3, -px * py / r3, -px * py / r3, px * px / r3)
        } else {
            let r4 = r2 * r2;
            Matrix2::new(
                2.0 * px * py / r4,
                (py * py - px * px) / r4,
                (py * py - px * px) / r4,
                -2.0 * px * py / r4,
            )
        };
        h.fixed_view_mut::<2, 2>(0, 0).copy_from(&block);
        Some(h)
    }
}

#[test]
fn process_and_measurement_models() {
    let u = Vector2::new(0.3, -0.2);
    for x in [
        OVector::<f64, U4>::new(1.0, 2.0, 0.4, 3.0),
        OVector::<f64, U4>::new(-2.0, 0.5, 2.9, 1.5),
    ] {
        assert_accurate(
            "unicycle",
            derivative::check_process_model(
                &Unicycle {
                    wrong_jacobian: false,
                },
                &x,
                &u,
                0.1,
            )
            .unwrap(),
            TOL,
        );
        let report = derivative::check_process_jacobian(
            &Unicycle {
                wrong_jacobian: true,
            },
            &x,
            &u,
            0.1,
        )
        .unwrap();
        assert!(!report.is_accurate(TOL), "{report}");
        assert_eq!(
            report.worst_mixed.unwrap().entry,
            Entry::Jacobian { row: 1, col: 3 }
        );
        assert_accurate(
            "range-bearing",
            derivative::check_measurement_model(
                &RangeBearing {
                    plain_residual: false,
                },
                &x,
            )
            .unwrap(),
            TOL,
        );
        assert_accurate(
            "range-bearing J",
            derivative::check_measurement_jacobian(
                &RangeBearing {
                    plain_residual: false,
                },
                &x,
            )
            .unwrap(),
            TOL,
        );
    }
}

/// On the bearing's branch cut (target behind, py ≈ 0, px < 0) the two finite-difference
/// points straddle ±π. The checker differences through the model's residual, so a wrapped
/// residual passes; the plain one sees a 2π jump (and is flagged), which shows the wrapping
/// is what makes it pass.
#[test]
fn wrapped_residuals_are_used_for_finite_differences() {
    let x = OVector::<f64, U4>::new(-3.0, 0.0, 0.0, 0.0);
    assert_accurate(
        "wrapped bearing at ±π",
        derivative::check_measurement_jacobian(
            &RangeBearing {
                plain_residual: false,
            },
            &x,
        )
        .unwrap(),
        TOL,
    );
    let report = derivative::check_measurement_jacobian(
        &RangeBearing {
            plain_residual: true,
        },
        &x,
    )
    .unwrap();
    assert!(!report.is_accurate(TOL), "{report}");
    assert_eq!(
        report.worst_abs.unwrap().entry,
        Entry::Jacobian { row: 1, col: 1 }
    );
}

#[test]
fn invalid_settings_and_inputs() {
    for step in [0.0, -1e-6, f64::NAN, f64::INFINITY] {
        match DerivativeCheck::with_relative_step(step) {
            Err(Error::InvalidParameter {
                parameter: Parameter::StepSize,
                ..
            }) => {}
            other => panic!("step {step}: {other:?}"),
        }
    }
    assert!(DerivativeCheck::with_relative_step(1e-4).is_ok());
    // A custom step still works.
    let check = DerivativeCheck::with_relative_step(1e-4).unwrap();
    // h = 10⁻⁴: truncation h²M₃/6 ≈ 10⁻⁸·M₃/6 ≲ 2·10⁻⁷ for M₃ ≤ 100 (below 1e-6).
    assert_accurate(
        "custom step",
        check
            .derivatives(&TrigSum::products(U3, U3), &Vector3::new(0.5, 1.0, -1.0))
            .unwrap(),
        TOL,
    );

    let products = TrigSum::products(U3, U3);
    assert_eq!(
        derivative::check_derivatives(&products, &Vector3::new(f64::NAN, 0.0, 0.0)),
        Err(Error::NonFinite {
            stage: Stage::DerivativeCheck,
            quantity: Quantity::Mean
        })
    );
}

/// A dynamic-size function whose Jacobian or Hessian has the wrong shape, or whose output
/// length changes with x: the checker returns DimensionMismatch, it does not panic.
struct Misshapen {
    jacobian_rows: usize,
    hessian_dim: usize,
    /// Output length 3 instead of 2 when x₀ > this.
    grow_above: f64,
    /// `difference_into` returns this many entries instead of the output length.
    difference_len: Option<usize>,
}

impl VectorFunction<f64, Dyn, Dyn> for Misshapen {
    fn eval(&self, x: &OVector<f64, Dyn>) -> OVector<f64, Dyn> {
        let m = if x[0] > self.grow_above { 3 } else { 2 };
        OVector::<f64, Dyn>::from_fn(m, |i, _| x[0] * (i + 1) as f64)
    }

    fn difference_into(
        &self,
        a: &OVector<f64, Dyn>,
        b: &OVector<f64, Dyn>,
        out: &mut OVector<f64, Dyn>,
    ) {
        *out = match self.difference_len {
            Some(len) => OVector::<f64, Dyn>::zeros(len),
            None => a - b,
        };
    }
}

impl Differentiable<f64, Dyn, Dyn> for Misshapen {
    fn jacobian(&self, x: &OVector<f64, Dyn>) -> OMatrix<f64, Dyn, Dyn> {
        OMatrix::<f64, Dyn, Dyn>::from_fn(self.jacobian_rows, x.len(), |i, j| {
            if j == 0 { (i + 1) as f64 } else { 0.0 }
        })
    }
}

impl TwiceDifferentiable<f64, Dyn, Dyn> for Misshapen {
    fn hessian(&self, _: &OVector<f64, Dyn>, _: usize) -> Option<OMatrix<f64, Dyn, Dyn>> {
        Some(OMatrix::<f64, Dyn, Dyn>::zeros(
            self.hessian_dim,
            self.hessian_dim,
        ))
    }
}

#[test]
fn dynamic_shape_errors_are_reported() {
    let x = OVector::<f64, Dyn>::from_vec(vec![1.0, 2.0, 3.0]);
    let ok = Misshapen {
        jacobian_rows: 2,
        hessian_dim: 3,
        grow_above: f64::INFINITY,
        difference_len: None,
    };
    assert_accurate(
        "well-shaped",
        derivative::check_derivatives(&ok, &x).unwrap(),
        TOL,
    );
    let mismatch = |r: Result<_, Error>, quantity, (er, ec), (fr, fc)| {
        assert_eq!(
            r.map(|_: derivative::DerivativeReport<f64>| ()),
            Err(Error::DimensionMismatch {
                stage: Stage::DerivativeCheck,
                quantity,
                expected_rows: er,
                expected_cols: ec,
                found_rows: fr,
                found_cols: fc
            })
        );
    };
    mismatch(
        derivative::check_jacobian(
            &Misshapen {
                jacobian_rows: 3,
                ..ok
            },
            &x,
        ),
        Quantity::Jacobian,
        (2, 3),
        (3, 3),
    );
    mismatch(
        derivative::check_derivatives(
            &Misshapen {
                hessian_dim: 2,
                ..ok
            },
            &x,
        ),
        Quantity::Hessian,
        (3, 3),
        (2, 2),
    );
    // The output grows to length 3 at x₀ + h: a function-value mismatch.
    mismatch(
        derivative::check_jacobian(
            &Misshapen {
                grow_above: 1.0,
                ..ok
            },
            &x,
        ),
        Quantity::FunctionValue,
        (2, 1),
        (3, 1),
    );
}

/// The TrigSum Hessians used throughout these tests are exactly symmetric.
#[test]
fn static_hessians_are_symmetric() {
    let products = TrigSum::products(U3, U3);
    let x = Vector3::new(0.2, -1.3, 0.7);
    for k in 0..3 {
        if let Some(h) = products.hessian(&x, k) {
            let h: Matrix3<f64> = h;
            approx::assert_abs_diff_eq!(h, h.transpose(), epsilon = 0.0);
        }
    }
}

/// The checker on a state space (issue 38): an attitude held as the rotation vector θ of
/// q = Exp(θ) under [`AttitudeError`], with a scale s. The filters use the Jacobian on the
/// manifold, F = ∂(f(x ⊞ δ) ⊟ f(x))/∂δ, which differs from ∂f/∂x of the coordinates wherever
/// θ ≠ 0: the state-space check passes the correct one and flags a corrupted entry; the
/// coordinate check flags the correct one.
mod on_a_state_space {
    use super::*;
    use estim_core::derivative::{check_measurement_jacobian_on, check_process_jacobian_on};
    use estim_core::manifold::{AttitudeError, so3_exp, so3_log};
    use estim_core::nalgebra::{Matrix3x4, Matrix4, Vector4};

    /// θ⁺ = Log(Exp(θ) Exp(ω Δt)), s⁺ = s.
    struct Turn {
        wrong: f64,
    }
    impl ProcessModel<f64, U4> for Turn {
        type Input = Vector3<f64>;
        fn transition(&self, x: &Vector4<f64>, w: &Vector3<f64>, dt: f64) -> Vector4<f64> {
            let theta = so3_log(&(so3_exp(&x.xyz()) * so3_exp(&(w * dt))));
            Vector4::new(theta[0], theta[1], theta[2], x[3])
        }
        fn process_noise(&self, _: &Vector4<f64>, _: &Vector3<f64>, _: f64) -> Matrix4<f64> {
            Matrix4::identity() * 1e-6
        }
    }
    impl ProcessJacobian<f64, U4> for Turn {
        /// A body-frame error δ before the step is R(ω Δt)ᵀ δ after it.
        fn transition_jacobian(&self, _: &Vector4<f64>, w: &Vector3<f64>, dt: f64) -> Matrix4<f64> {
            let r = so3_exp(&(w * dt)).to_rotation_matrix().into_inner();
            let mut f = Matrix4::identity();
            f.fixed_view_mut::<3, 3>(0, 0).copy_from(&r.transpose());
            f[(1, 2)] += self.wrong;
            f
        }
    }

    /// z = (1 + s) R(q)ᵀ m: a scaled magnetometer.
    struct Field {
        m: Vector3<f64>,
        wrong: f64,
    }
    impl MeasurementModel<f64, U4, U3> for Field {
        fn measure(&self, x: &Vector4<f64>) -> Vector3<f64> {
            (so3_exp(&x.xyz()).inverse() * self.m) * (1.0 + x[3])
        }
        fn measurement_noise(&self, _: &Vector4<f64>) -> Matrix3<f64> {
            Matrix3::identity() * 1e-4
        }
    }
    impl MeasurementJacobian<f64, U4, U3> for Field {
        /// (R Exp(δ))ᵀ m ≈ Rᵀm + [Rᵀm]× δ.
        fn measurement_jacobian(&self, x: &Vector4<f64>) -> Matrix3x4<f64> {
            let b = so3_exp(&x.xyz()).inverse() * self.m;
            let mut h = Matrix3x4::zeros();
            h.fixed_view_mut::<3, 3>(0, 0)
                .copy_from(&(b.cross_matrix() * (1.0 + x[3])));
            h.set_column(3, &b);
            h[(0, 1)] += self.wrong;
            h
        }
    }

    fn ball(radius: f64) -> impl Strategy<Value = Vector3<f64>> {
        prop::array::uniform3(-1.0..1.0f64)
            .prop_filter("inside the unit ball", |v| Vector3::from(*v).norm() <= 1.0)
            .prop_map(move |v| Vector3::from(v) * radius)
    }

    proptest! {
        #![proptest_config(config(64, 0x38d3))]

        #[test]
        fn manifold_jacobians_pass_on_the_space_and_fail_in_coordinates(
            theta in ball(2.5), w in ball(4.0), s in -0.2..0.2f64,
        ) {
            // |θ| ≥ 0.3 so that the coordinate Jacobian differs by O(|θ| |ω Δt|) ≫ TOL.
            prop_assume!(theta.norm() > 0.3 && w.norm() > 1.0);
            let x = Vector4::new(theta[0], theta[1], theta[2], s);
            let space = AttitudeError::at(0);
            let dt = 0.1;
            let m = Vector3::new(0.2, -0.05, 0.45);
            let right = check_process_jacobian_on(&space, &Turn { wrong: 0.0 }, &x, &w, dt).unwrap();
            prop_assert!(right.is_accurate(TOL), "{right}");
            let wrong = check_process_jacobian_on(&space, &Turn { wrong: 1e-3 }, &x, &w, dt).unwrap();
            prop_assert!(!wrong.is_accurate(TOL), "{wrong}");
            prop_assert_eq!(wrong.worst_mixed.unwrap().entry, Entry::Jacobian { row: 1, col: 2 });
            let embedded = derivative::check_process_jacobian(&Turn { wrong: 0.0 }, &x, &w, dt).unwrap();
            prop_assert!(!embedded.is_accurate(1e-3), "{embedded}");

            let right = check_measurement_jacobian_on(&space, &Field { m, wrong: 0.0 }, &x).unwrap();
            prop_assert!(right.is_accurate(TOL), "{right}");
            let wrong = check_measurement_jacobian_on(&space, &Field { m, wrong: 1e-3 }, &x).unwrap();
            prop_assert_eq!(wrong.worst_mixed.unwrap().entry, Entry::Jacobian { row: 0, col: 1 });
            prop_assert!(!wrong.is_accurate(TOL), "{wrong}");
            let embedded = derivative::check_measurement_jacobian(&Field { m, wrong: 0.0 }, &x).unwrap();
            prop_assert!(!embedded.is_accurate(1e-3), "{embedded}");
        }
    }
}
