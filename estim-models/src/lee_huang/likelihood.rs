//! The velocity "measurement likelihood" g(D) that feeds the OTE (eq 27/28 = 30/31 form,
//! erratum E2), with its analytic Jacobian and Hessians.
//!
//! With p = (x₁, x₂), v = (x₃, x₄), d = |p|, ρ̇ = p·v/d, û = (cos x₅, sin x₅),
//! n̂ = (−sin x₅, cos x₅) (x₅ = θ, x₆ = ω: body attitude and rate, as the paper substitutes):
//!
//! ```text
//! g(D) = ρ̇ û + d x₆ n̂
//! ∂g_c/∂p = ∇ₚρ̇ û_c + x₆ (p/d) n̂_c,  ∇ₚρ̇ = (v − ρ̇ p/d)/d
//! ∂g_c/∂v = (p/d) û_c,   ∂g_c/∂x₅ = ρ̇ n̂_c − d x₆ û_c,   ∂g_c/∂x₆ = d n̂_c
//! Hessian blocks (symmetric, others 0), ∇²d = I/d − p pᵀ/d³,
//!   ∇²ₚₚρ̇ = −(v pᵀ + p vᵀ)/d³ − ρ̇ (I/d² − 3 p pᵀ/d⁴):
//! [p,p] = ∇²ₚₚρ̇ û_c + x₆ ∇²d n̂_c   [p,v] = ∇²d û_c   [p,x₅] = ∇ₚρ̇ n̂_c − x₆ (p/d) û_c
//! [p,x₆] = (p/d) n̂_c   [v,x₅] = (p/d) n̂_c   [x₅,x₅] = −g_c   [x₅,x₆] = −d û_c
//! ```
//!
//! If x₅ were the bearing of p and x₆ its rate, g(D) would equal (v_x, v_y) identically
//! (eq 27–29 are then a change of coordinates, erratum E10); with the body attitude it encodes
//! the assumption "velocity along the body axis along the position bearing" (radial flight).
//! g is undefined at d = 0.

use estim_core::{Differentiable, TwiceDifferentiable, VectorFunction};
use nalgebra::{Matrix2, Matrix2x6, Matrix6, U2, U6, Vector2, Vector6};
// f64's float functions without std (libm); with std the inherent methods are used.
#[cfg(not(feature = "std"))]
use num_traits::Float as _;

/// Which formula of the paper builds the pseudo-measurement.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum LikelihoodForm {
    /// eq 27/28 (= 30/31): g = ρ̇ û + d x₆ n̂ ([`VelocityLikelihood`]). estim's default.
    #[default]
    Consistent,
    /// eq 38/39 as printed: (ρ̇ sin x₅ − d x₆ cos x₅, ρ̇ cos x₅ + d x₆ sin x₅)
    /// ([`velocity_likelihood_as_printed`]); kept to show erratum E2.
    AsPrinted,
}

impl LikelihoodForm {
    /// Evaluates the chosen form at D.
    pub fn eval(self, d: &Vector6<f64>) -> Vector2<f64> {
        match self {
            LikelihoodForm::Consistent => VelocityLikelihood.eval(d),
            LikelihoodForm::AsPrinted => velocity_likelihood_as_printed(d),
        }
    }
}

/// g(D) of eq 27/28 as a twice-differentiable vector function ℝ⁶ → ℝ² (see the
/// [module docs](self)).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct VelocityLikelihood;

struct Parts {
    p: Vector2<f64>,
    v: Vector2<f64>,
    d: f64,
    rho_dot: f64,
    u: Vector2<f64>,
    n: Vector2<f64>,
    w: f64,
}

fn parts(x: &Vector6<f64>) -> Parts {
    let p = Vector2::new(x[0], x[1]);
    let v = Vector2::new(x[2], x[3]);
    let d = p.norm();
    let (s, c) = x[4].sin_cos();
    Parts {
        p,
        v,
        d,
        rho_dot: p.dot(&v) / d,
        u: Vector2::new(c, s),
        n: Vector2::new(-s, c),
        w: x[5],
    }
}

impl VectorFunction<f64, U6, U2> for VelocityLikelihood {
    fn eval(&self, x: &Vector6<f64>) -> Vector2<f64> {
        let q = parts(x);
        q.u * q.rho_dot + q.n * (q.d * q.w)
    }
}

impl Differentiable<f64, U6, U2> for VelocityLikelihood {
    fn jacobian(&self, x: &Vector6<f64>) -> Matrix2x6<f64> {
        let q = parts(x);
        let pd = q.p / q.d;
        let grad_rho = (q.v - pd * q.rho_dot) / q.d;
        let mut j = Matrix2x6::zeros();
        for c in 0..2 {
            for i in 0..2 {
                j[(c, i)] = grad_rho[i] * q.u[c] + q.w * pd[i] * q.n[c];
                j[(c, 2 + i)] = pd[i] * q.u[c];
            }
            j[(c, 4)] = q.rho_dot * q.n[c] - q.d * q.w * q.u[c];
            j[(c, 5)] = q.d * q.n[c];
        }
        j
    }
}

impl TwiceDifferentiable<f64, U6, U2> for VelocityLikelihood {
    fn hessian(&self, x: &Vector6<f64>, k: usize) -> Option<Matrix6<f64>> {
        if k > 1 {
            return None;
        }
        let q = parts(x);
        let (d, d2) = (q.d, q.d * q.d);
        let pd = q.p / d;
        let ppt = q.p * q.p.transpose();
        let hess_d = Matrix2::identity() / d - ppt / (d2 * d);
        let hess_rho = -(q.v * q.p.transpose() + q.p * q.v.transpose()) / (d2 * d)
            - (Matrix2::identity() / d2 - ppt * (3.0 / (d2 * d2))) * q.rho_dot;
        let grad_rho = (q.v - pd * q.rho_dot) / d;
        let (uc, nc) = (q.u[k], q.n[k]);
        let gc = q.rho_dot * uc + d * q.w * nc;

        let mut h = Matrix6::zeros();
        let pp = hess_rho * uc + hess_d * (q.w * nc);
        let pv = hess_d * uc;
        for i in 0..2 {
            for j in 0..2 {
                h[(i, j)] = pp[(i, j)];
                h[(i, 2 + j)] = pv[(i, j)];
                h[(2 + j, i)] = pv[(i, j)];
            }
            let p5 = grad_rho[i] * nc - q.w * pd[i] * uc;
            let p6 = pd[i] * nc;
            let v5 = pd[i] * nc;
            h[(i, 4)] = p5;
            h[(4, i)] = p5;
            h[(i, 5)] = p6;
            h[(5, i)] = p6;
            h[(2 + i, 4)] = v5;
            h[(4, 2 + i)] = v5;
        }
        h[(4, 4)] = -gc;
        h[(4, 5)] = -d * uc;
        h[(5, 4)] = -d * uc;
        Some(h)
    }
}

/// eq 38/39 exactly as printed (sin and cos swapped against eq 27/28, erratum E2).
pub fn velocity_likelihood_as_printed(x: &Vector6<f64>) -> Vector2<f64> {
    let q = parts(x);
    let (s, c) = x[4].sin_cos();
    Vector2::new(q.rho_dot * s - q.d * q.w * c, q.rho_dot * c + q.d * q.w * s)
}
