//! The main job: reproduces the papers' results.
//!
//! So far: Boje's worked second-order moment examples (eq 8, 10, 11) computed by the *generic*
//! propagators on the underlying functions, beside the exact Gaussian values and a 10⁶-sample
//! Monte Carlo. Run with `cargo run --release --example papers [-- --json]`.

use estim::nalgebra::{Matrix2, U2, Vector2};
use estim::prelude::*;

/// g(x, θ) = (cos θ, sin θ, x cos θ, x sin θ) for the state (x, θ).
struct BojeTrig;

impl VectorFunction<f64, U2, estim::nalgebra::U4> for BojeTrig {
    fn eval(&self, s: &Vector2<f64>) -> estim::nalgebra::Vector4<f64> {
        let (x, th) = (s[0], s[1]);
        estim::nalgebra::Vector4::new(th.cos(), th.sin(), x * th.cos(), x * th.sin())
    }
}

impl Differentiable<f64, U2, estim::nalgebra::U4> for BojeTrig {
    fn jacobian(&self, s: &Vector2<f64>) -> estim::nalgebra::Matrix4x2<f64> {
        let (x, th) = (s[0], s[1]);
        let (c, si) = (th.cos(), th.sin());
        estim::nalgebra::Matrix4x2::new(0.0, -si, 0.0, c, c, -x * si, si, x * c)
    }
}

impl TwiceDifferentiable<f64, U2, estim::nalgebra::U4> for BojeTrig {
    fn hessian(&self, s: &Vector2<f64>, k: usize) -> Option<Matrix2<f64>> {
        let (x, th) = (s[0], s[1]);
        let (c, si) = (th.cos(), th.sin());
        Some(match k {
            0 => Matrix2::new(0.0, 0.0, 0.0, -c),
            1 => Matrix2::new(0.0, 0.0, 0.0, -si),
            2 => Matrix2::new(0.0, -si, -si, -x * c),
            _ => Matrix2::new(0.0, c, c, -x * si),
        })
    }
}

/// Exact moments for independent Gaussian x ~ N(x̄, σx²), θ ~ N(θ̄, σθ²).
fn exact(xm: f64, sx: f64, tm: f64, st: f64) -> [f64; 7] {
    let e1 = (-st * st / 2.0).exp();
    let e2 = (-2.0 * st * st).exp();
    let (ec, es) = (tm.cos() * e1, tm.sin() * e1);
    let (ec2, es2) = (
        0.5 * (1.0 + e2 * (2.0 * tm).cos()),
        0.5 * (1.0 - e2 * (2.0 * tm).cos()),
    );
    let ex2 = xm * xm + sx * sx;
    [
        ec,
        es,
        ec2 - ec * ec,
        es2 - es * es,
        xm * ec,
        ex2 * ec2 - (xm * ec).powi(2),
        ex2 * es2 - (xm * es).powi(2),
    ]
}

fn pick(m: &estim::core::Moments<f64, U2, estim::nalgebra::U4>) -> [f64; 7] {
    let c = &m.covariance;
    [
        m.mean[0],
        m.mean[1],
        c[(0, 0)],
        c[(1, 1)],
        m.mean[2],
        c[(2, 2)],
        c[(3, 3)],
    ]
}

fn main() -> Result<(), Error> {
    let json = std::env::args().any(|a| a == "--json");
    let (xm, sx, tm, st) = (2.0, 0.3, 0.7, 0.1);
    let prior = Gaussian::new(
        Vector2::new(xm, tm),
        Matrix2::new(sx * sx, 0.0, 0.0, st * st),
    )?;
    let second = pick(&SecondOrder.propagate_gaussian(&prior, &BojeTrig)?);
    let sampled = pick(&Sampled::new(1_000_000, 2026)?.propagate_gaussian(&prior, &BojeTrig)?);
    let exact = exact(xm, sx, tm, st);
    let names = [
        "e_cos",
        "e_sin",
        "var_cos",
        "var_sin",
        "e_x_cos",
        "var_x_cos",
        "var_x_sin",
    ];

    println!(
        "Boje eq 8, 10, 11 (Papoulis second order) for θ ~ N({tm}, {st}²), x ~ N({xm}, {sx}²)"
    );
    println!(
        "{:<10} {:>14} {:>14} {:>14} {:>10}",
        "quantity", "second order", "exact", "sampled 1e6", "rel err"
    );
    for i in 0..names.len() {
        println!(
            "{:<10} {:>14.8} {:>14.8} {:>14.8} {:>10.2e}",
            names[i],
            second[i],
            exact[i],
            sampled[i],
            (second[i] - exact[i]) / exact[i]
        );
    }
    if json {
        let body: Vec<String> = (0..names.len())
            .map(|i| {
                format!(
                    "\"{}\":{{\"second_order\":{:e},\"exact\":{:e},\"sampled\":{:e}}}",
                    names[i], second[i], exact[i], sampled[i]
                )
            })
            .collect();
        println!("{{\"boje_moments\":{{{}}}}}", body.join(","));
    }
    Ok(())
}
