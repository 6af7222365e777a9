//! The distribution functions behind the χ² thresholds, against reference values (SciPy 1.17
//! `scipy.special.erfc`, `scipy.stats.chi2`, `ncx2`, `norm`, computed outside the repo).

use estim_models::lv2::stats::{
    chi2_1_cdf, chi2_1_power, chi2_quantile_upper, chi2_sf, erfc, normal_cdf,
};

/// |a − b| ≤ tol · |b|.
fn close(a: f64, b: f64, tol: f64) -> bool {
    (a - b).abs() <= tol * b.abs()
}

#[test]
fn erfc_matches_reference() {
    // erfc(x) = Q(½, x²) on statrs: measured ≤ 1.1e-14 relative over these cases (worst at
    // x = 10). The cases (and the 1e-13 bound) were chosen for the former hand-rolled series /
    // continued fraction switching at 2.5; statrs' own `erf::erfc` misses 1e-13 (1e-10).
    let cases = [
        (0.01, 0.9887165844441503),
        (0.5, 0.4795001221869535),
        (1.0, 0.15729920705028513),
        (2.0, 0.004677734981047265),
        (2.49, 0.00042928786773391303),
        (2.5, 0.0004069520174449589),
        (2.51, 0.0003857054817242799),
        (3.0, 2.2090496998585438e-05),
        (5.0, 1.5374597944280351e-12),
        (6.0, 2.1519736712498913e-17),
        (10.0, 2.088487583762545e-45),
        (-1.2, 1.9103139782296354),
    ];
    for (x, want) in cases {
        let got = erfc(x);
        assert!(
            close(got, want, 1e-13),
            "erfc({x}) = {got:e}, want {want:e}"
        );
    }
    assert_eq!(erfc(0.0), 1.0);
    assert!(erfc(f64::NAN).is_nan());
    assert!(close(normal_cdf(-1.5), 0.06680720126885807, 1e-13));
    assert!(close(normal_cdf(0.3), 0.6179114221889526, 1e-13));
}

#[test]
fn chi2_survival_and_quantiles_match_reference() {
    // statrs' Q(k/2, x/2): agreement to ≈ 1e-15 measured; the quantile bisects it.
    let sf = [
        (0.5, 1, 0.47950012218695337),
        (25.0, 1, 5.733031437583875e-07),
        (1e-6, 2, 0.999999500000125),
        (40.0, 3, 1.065509033425585e-08),
        (7.5, 4, 0.11170929281604328),
        (3.0, 5, 0.6999858358786276),
        (2.0, 7, 0.9598403687301016),
        (100.0, 10, 5.4497019829205215e-17),
    ];
    for (x, k, want) in sf {
        let got = chi2_sf(x, k);
        assert!(
            close(got, want, 1e-12),
            "sf({x}, {k}) = {got:e}, want {want:e}"
        );
    }
    let q = [
        (1e-3, 1, 10.827566170662733),
        (1e-2, 1, 6.6348966010212145),
        (1e-3, 2, 13.815510557964274),
        (1e-3, 3, 16.26623619623813),
    ];
    for (alpha, k, want) in q {
        let got = chi2_quantile_upper(alpha, k);
        assert!(
            close(got, want, 1e-12),
            "quantile({alpha}, {k}) = {got}, want {want}"
        );
    }
    assert_eq!(chi2_sf(0.0, 3), 1.0);
    assert_eq!(chi2_sf(1.0, 0), 0.0);
    for k in 1..6 {
        assert_eq!(chi2_sf(f64::INFINITY, k), 0.0, "sf(∞, {k})");
    }
    assert!(chi2_quantile_upper(0.0, 1).is_nan());
    assert!(chi2_quantile_upper(0.1, 0).is_nan());
}

#[test]
fn noncentral_one_dof_matches_reference() {
    // ncx2(df = 1, nc = δ²): the power at the α = 1e-3 threshold for δ = 2, and a CDF value.
    let c = 10.827566170662733;
    assert!(close(chi2_1_power(2.0, c), 0.09843397932526189, 1e-12));
    assert!(close(chi2_1_power(-2.0, c), 0.09843397932526189, 1e-12));
    assert!(close(chi2_1_power(0.0, c), 1e-3, 1e-12));
    assert!(close(chi2_1_cdf(5.0, 3.0), 0.22245379457681652, 1e-12));
    assert!(close(chi2_1_cdf(5.0, 0.0), 1.0 - chi2_sf(5.0, 1), 1e-14));
}

/// Many degrees of freedom (a runtime-size fusion with thousands of redundant axes), where
/// e^{−x/2} alone underflows while the survival is of order one. Reference: mpmath 1.3
/// `gammainc(k/2, x/2, inf, regularized=True)` at 50 digits, and `findroot` on it for the
/// quantiles (computed outside the repo).
#[test]
fn chi2_survival_holds_at_many_degrees_of_freedom() {
    let sf = [
        (2100.0, 2000, 0.05867111137731808),
        (1600.0, 1500, 0.03602644670402662),
        (2000.0, 2000, 0.4957947558197845),
        (1900.0, 2001, 0.946698227661073),
        (2400.0, 2000, 1.2881606086281433e-9),
        (3000.0, 2999, 0.49141597304373613),
        (9000.0, 10000, 0.999999999999873),
    ];
    for (x, k, want) in sf {
        let got = chi2_sf(x, k);
        // Bound kept from the former finite log-sum (k/2 steps each rounding by ≤ 2 ulp of
        // |ln tⱼ| ≤ x/2: k x ε / 2 relative, 4.7e-10 at the first case); statrs' Q(k/2, x/2)
        // measures ≤ 1.3e-12 on these cases.
        let tol = k as f64 * x * f64::EPSILON / 2.0;
        assert!(
            close(got, want, tol),
            "sf({x}, {k}) = {got:e}, want {want:e}"
        );
    }
    let q = [
        (1e-2, 2000, 2150.06566417287),
        (1e-3, 1500, 1674.9736208470572),
    ];
    for (alpha, k, want) in q {
        let got = chi2_quantile_upper(alpha, k);
        // The survival's relative error δ ≈ 5e-12 moves the root by δ·sf/pdf ≈ 1e-13 here.
        assert!(
            close(got, want, 1e-12),
            "quantile({alpha}, {k}) = {got}, want {want}"
        );
    }
    // Beyond the smallest float: 0, not NaN (χ²₂ at 1490: 2.8e-324 exactly).
    assert!(chi2_sf(1e4, 2) == 0.0 && chi2_sf(1e4, 5001) < 1e-300);
}

/// Degrees of freedom above the limit give NaN at once: statrs' series would stall (for
/// ≳ 2⁵⁴ it never returned). The limit itself is evaluated: the upper 1 % point of χ²ₖ is
/// k + 2.326 √(2k) to within 10⁻³ of the offset at k = 2³⁶.
#[test]
fn degrees_of_freedom_beyond_the_limit_give_nan() {
    use estim_models::lv2::stats::MAX_DEGREES_OF_FREEDOM;
    assert!(chi2_sf(1.0, MAX_DEGREES_OF_FREEDOM + 1).is_nan());
    assert!(chi2_sf((1u64 << 60) as f64, 1 << 60).is_nan());
    assert!(chi2_quantile_upper(0.01, usize::MAX).is_nan());
    let k = MAX_DEGREES_OF_FREEDOM as f64;
    let offset = chi2_quantile_upper(0.01, MAX_DEGREES_OF_FREEDOM) - k;
    let expected = 2.326_347_874_040_841 * (2.0 * k).sqrt();
    assert!(
        (offset - expected).abs() < 1e-3 * expected,
        "{offset} vs {expected}"
    );
}
