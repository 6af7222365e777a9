//! Checks made of many single tests, and the verdict over all of them.

use core::fmt;

use crate::validation::Result;
use statrs::function::gamma::ln_gamma;

use super::validate_confidence;

/// A consistency check: one property of a consistent filter, tested at many time slots (or
/// lags, or matrix entries).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub enum Check {
    /// E\[e\] = 0: each component of the ensemble mean error, t = ē / (s/√N) against Student's
    /// t with N − 1 degrees of freedom (Lu's "actual mean ≈ 0").
    MeanError,
    /// Ensemble error variance = filter variance: each diagonal ratio (P_ens)ᵢᵢ / (P̄)ᵢᵢ against
    /// χ²_{N−1}/(N−1) (Lu's "P^ave − P ≈ 0").
    ErrorCovariance,
    /// Average NEES ε̄ = (1/N) Σ eᵀP⁻¹e against χ²_{N·n}/N.
    Nees,
    /// Average NIS against χ²_{N·m}/N.
    Nis,
    /// E[(e − ē) x̂ᵀ] = 0: each sample correlation of an error component with an estimate
    /// component against its t-based bound (Lu's orthogonality check).
    Orthogonality,
    /// Residuals at two chosen times uncorrelated: each normalised entry of
    /// (1/N) Σ r(a) r(b)ᵀ against ±z/√N (Lu's residual check).
    ResidualCorrelation,
    /// One run's innovation autocorrelation at chosen lags against ±z/√K.
    Whiteness,
}

impl Check {
    /// A short name for tables.
    pub fn name(self) -> &'static str {
        match self {
            Check::MeanError => "mean error = 0",
            Check::ErrorCovariance => "ensemble cov = filter cov",
            Check::Nees => "average NEES",
            Check::Nis => "average NIS",
            Check::Orthogonality => "error ⟂ estimate",
            Check::ResidualCorrelation => "residuals uncorrelated",
            Check::Whiteness => "innovation whiteness",
        }
    }
}

impl fmt::Display for Check {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// What a single test refers to.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Location {
    /// A time slot (scalar statistics: NEES, NIS).
    Slot {
        /// Slot index.
        slot: usize,
    },
    /// A state component at a slot (mean error, covariance ratio).
    Component {
        /// Slot index.
        slot: usize,
        /// State component.
        component: usize,
    },
    /// Entry (error component `row`, estimate component `col`) at a slot (orthogonality).
    Entry {
        /// Slot index.
        slot: usize,
        /// Row (error component).
        row: usize,
        /// Column (estimate component).
        col: usize,
    },
    /// Entry (`row` of r(first), `col` of r(second)) of a residual pair.
    Pair {
        /// The first slot a.
        first: usize,
        /// The second slot b.
        second: usize,
        /// Component of r(a).
        row: usize,
        /// Component of r(b).
        col: usize,
    },
    /// An autocorrelation lag.
    Lag {
        /// The lag.
        lag: usize,
    },
}

impl fmt::Display for Location {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Location::Slot { slot } => write!(f, "slot {slot}"),
            Location::Component { slot, component } => write!(f, "slot {slot} [{component}]"),
            Location::Entry { slot, row, col } => write!(f, "slot {slot} [{row},{col}]"),
            Location::Pair {
                first,
                second,
                row,
                col,
            } => write!(f, "slots {first}×{second} [{row},{col}]"),
            Location::Lag { lag } => write!(f, "lag {lag}"),
        }
    }
}

/// The most extreme single test of a check: the one with the smallest p-value.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Worst {
    /// Where.
    pub location: Location,
    /// The statistic (t, ratio, average NEES/NIS, correlation).
    pub value: f64,
    /// Lower end of its band at the per-test confidence.
    pub lower: f64,
    /// Upper end of its band.
    pub upper: f64,
    /// Its two-sided p-value under consistency.
    pub p_value: f64,
}

/// A check's outcome.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Outcome {
    /// Passed: its p-value exceeds 1 − confidence.
    Pass,
    /// Failed.
    Fail,
    /// Nothing to test (e.g. no innovations recorded, no residual pair requested, or too few
    /// runs). Counts as passing in [`Verdict::consistent`].
    NotRun,
}

/// How the single tests of a check are combined into its decision.
///
/// Each single test (one slot, one component, ...) has a two-sided p-value p under
/// consistency. A check with T tests must not fail merely because, among many tests, a few are
/// extreme by chance; and the tests of neighbouring time slots are strongly *dependent*
/// (filter errors are correlated in time; a slowly observable state such as a sensor bias keeps
/// its error for the whole run), so rules that count tests as independent evidence raise
/// false alarms.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum FamilyRule {
    /// The default. Simes' test (Simes 1986): with p₍₁₎ ≤ … ≤ p₍T₎ sorted, the check's
    /// p-value is min_k T p₍k₎ / k, and the check fails when it is ≤ α = 1 − confidence.
    ///
    /// Its false-alarm probability is exactly α for independent tests and at most α for
    /// positively dependent ones (Sarkar 1998; Sarkar & Chang 1997 for the two-sided normal
    /// and t statistics used here), which is what time-correlated slots give. It includes
    /// Bonferroni (k = 1: fail when any p ≤ α/T) and also fails on several moderately small
    /// p-values together. Under arbitrary dependence the false-alarm probability is still
    /// below α (1 + ½ + … + 1/T) (Hommel 1983).
    Simes,
    /// For tests known to be independent (slots far apart compared with the error
    /// correlation time, whiteness lags): count the tests inside their two-sided band at
    /// `test_confidence` γ. With X ~ Binomial(T, γ) under consistency, the check's p-value is
    /// min(1, 2 min(P(X ≤ inside), T p_min)): rule one (too few inside: a systematic
    /// deviation too small to show in a single test) and rule two (a gross outlier,
    /// Bonferroni), each at α/2.
    ///
    /// This is more powerful than Simes against small deviations spread over many
    /// independent tests, but with dependent tests the count of tests outside is
    /// over-dispersed and it fails far more often than α: on the 3-state Kalman filter of
    /// this crate's tests, with 20 slots 0.5 s apart, every check at 99% (γ = 95%) failed in
    /// 44 of 200 seeds (22%) where ≤ 6% was designed, all by rule one of the mean-error,
    /// orthogonality, NEES and covariance checks.
    Binomial {
        /// γ, the confidence of each single test's band.
        test_confidence: f64,
    },
}

/// One check over many single tests, with its decision: see [`FamilyRule`].
#[derive(Clone, Debug, PartialEq)]
pub struct CheckResult {
    /// Which check.
    pub check: Check,
    /// The check's confidence 1 − α: it passes when `p_value` > α.
    pub confidence: f64,
    /// How the single tests were combined.
    pub rule: FamilyRule,
    /// The confidence of the single tests' bands (for `inside` and [`Worst`]): `confidence`
    /// under [`FamilyRule::Simes`], `test_confidence` under [`FamilyRule::Binomial`].
    pub band_confidence: f64,
    /// Number of single tests T.
    pub tests: usize,
    /// How many were inside their band.
    pub inside: usize,
    /// The check's p-value (1 when there are no tests): the check passes at every confidence
    /// c with 1 − c < p-value.
    pub p_value: f64,
    /// The test with the smallest p-value.
    pub worst: Option<Worst>,
    /// The decision.
    pub outcome: Outcome,
}

impl CheckResult {
    /// `true` unless the check failed ([`Outcome::NotRun`] passes).
    pub fn passed(&self) -> bool {
        self.outcome != Outcome::Fail
    }

    /// inside / tests (1 when there are no tests).
    pub fn fraction_inside(&self) -> f64 {
        if self.tests == 0 {
            1.0
        } else {
            self.inside as f64 / self.tests as f64
        }
    }
}

/// P(X ≤ k) for X ~ Binomial(`trials`, `p`), summed in log space (O(k)).
pub(crate) fn binomial_cdf(k: usize, trials: usize, p: f64) -> f64 {
    if k >= trials {
        return 1.0;
    }
    let t = trials as f64;
    let (ln_p, ln_q) = (p.ln(), (1.0 - p).ln());
    let ln_t_fact = ln_gamma(t + 1.0);
    let mut cdf = 0.0;
    for j in 0..=k {
        let jf = j as f64;
        cdf +=
            (ln_t_fact - ln_gamma(jf + 1.0) - ln_gamma(t - jf + 1.0) + jf * ln_p + (t - jf) * ln_q)
                .exp();
    }
    cdf.min(1.0)
}

/// Collects the single tests of one check and decides it.
#[derive(Clone, Debug)]
pub(crate) struct FamilyTest {
    check: Check,
    confidence: f64,
    rule: FamilyRule,
    band_confidence: f64,
    inside: usize,
    p_values: Vec<f64>,
    worst: Option<Worst>,
}

impl FamilyTest {
    pub(crate) fn new(check: Check, confidence: f64, rule: FamilyRule) -> Result<Self> {
        let band_confidence = match rule {
            FamilyRule::Simes => confidence,
            FamilyRule::Binomial { test_confidence } => test_confidence,
        };
        Ok(Self {
            check,
            confidence: validate_confidence(confidence)?,
            rule,
            band_confidence: validate_confidence(band_confidence)?,
            inside: 0,
            p_values: Vec::new(),
            worst: None,
        })
    }

    /// The confidence at which the single tests' bands are to be computed.
    pub(crate) fn band_confidence(&self) -> f64 {
        self.band_confidence
    }

    /// One test: `value` against [`lower`, `upper`], with its two-sided p-value (NaN counts
    /// as 0).
    pub(crate) fn add(
        &mut self,
        location: Location,
        value: f64,
        lower: f64,
        upper: f64,
        p_value: f64,
    ) {
        let p_value = if p_value.is_nan() { 0.0 } else { p_value };
        self.p_values.push(p_value);
        if lower <= value && value <= upper {
            self.inside += 1;
        }
        if self.worst.is_none_or(|w| p_value < w.p_value) {
            self.worst = Some(Worst {
                location,
                value,
                lower,
                upper,
                p_value,
            });
        }
    }

    pub(crate) fn finish(mut self) -> CheckResult {
        let tests = self.p_values.len();
        let t = tests as f64;
        let p_value = if tests == 0 {
            1.0
        } else {
            match self.rule {
                FamilyRule::Simes => {
                    self.p_values.sort_by(f64::total_cmp);
                    self.p_values
                        .iter()
                        .enumerate()
                        .map(|(k, &p)| t * p / (k + 1) as f64)
                        .fold(1.0f64, f64::min)
                }
                FamilyRule::Binomial { test_confidence } => {
                    let min_p = self.worst.map_or(1.0, |w| w.p_value);
                    let count = binomial_cdf(self.inside, tests, test_confidence);
                    (2.0 * count.min(t * min_p)).min(1.0)
                }
            }
        };
        let outcome = if tests == 0 {
            Outcome::NotRun
        } else if p_value > 1.0 - self.confidence {
            Outcome::Pass
        } else {
            Outcome::Fail
        };
        CheckResult {
            check: self.check,
            confidence: self.confidence,
            rule: self.rule,
            band_confidence: self.band_confidence,
            tests,
            inside: self.inside,
            p_value,
            worst: self.worst,
            outcome,
        }
    }
}

/// Which consistency checks pass, at which confidence: what
/// [`EnsembleStats::verdict`](crate::monte_carlo::EnsembleStats::verdict) returns.
///
/// Printing it gives a table, one row per check: the number of single tests, how many were
/// inside their band, the worst single test, the check's p-value and the outcome, e.g.
///
/// ```text
/// consistency verdict: 300 runs, confidence 95% per check (Simes): CONSISTENT
/// check                       tests  inside  worst single test                                    check p  result
/// mean error = 0                 60      57  slot 3 [1]: -2.4704 ∉ [-1.9679, 1.9679]             4.47e-1  pass
/// ensemble cov = filter cov      60      59  slot 11 [2]: 0.8385 ∉ [0.8461, 1.1665]              1.00e0   pass
/// ...
/// ```
///
/// In a test: `assert!(verdict.consistent(), "{verdict}")`.
#[derive(Clone, Debug, PartialEq)]
pub struct Verdict {
    /// Number of Monte Carlo runs behind the statistics (0 if not from a Monte Carlo run).
    pub runs: usize,
    /// The confidence of each check.
    pub confidence: f64,
    /// How each check combines its single tests.
    pub rule: FamilyRule,
    /// The checks, in the order run.
    pub checks: Vec<CheckResult>,
}

impl Verdict {
    /// `true` when no check failed and at least one ran: a verdict over nothing recorded
    /// (every check [`NotRun`](Outcome::NotRun)) is not evidence of consistency.
    pub fn consistent(&self) -> bool {
        self.checks.iter().all(CheckResult::passed)
            && self.checks.iter().any(|c| c.outcome != Outcome::NotRun)
    }

    /// The result of `check`, if it was run.
    pub fn check(&self, check: Check) -> Option<&CheckResult> {
        self.checks.iter().find(|c| c.check == check)
    }

    /// The outcome of `check` (`None` if it is not part of this verdict).
    pub fn outcome(&self, check: Check) -> Option<Outcome> {
        self.check(check).map(|c| c.outcome)
    }

    /// `true` if `check` is part of this verdict and failed.
    pub fn failed(&self, check: Check) -> bool {
        self.outcome(check) == Some(Outcome::Fail)
    }

    /// The checks that failed.
    pub fn failures(&self) -> impl Iterator<Item = &CheckResult> {
        self.checks.iter().filter(|c| !c.passed())
    }

    /// Adds another check (e.g. a [`Whiteness::check`](super::Whiteness::check)) to the
    /// verdict.
    pub fn push(&mut self, result: CheckResult) {
        self.checks.push(result);
    }
}

fn percent(x: f64) -> String {
    let p = 100.0 * x;
    if (p - p.round()).abs() < 1e-9 {
        format!("{p:.0}%")
    } else {
        format!("{p}%")
    }
}

impl fmt::Display for Verdict {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let rule = match self.rule {
            FamilyRule::Simes => "Simes".to_string(),
            FamilyRule::Binomial { test_confidence } => {
                format!(
                    "binomial count of single tests at {}",
                    percent(test_confidence)
                )
            }
        };
        writeln!(
            f,
            "consistency verdict: {} runs, confidence {} per check ({rule}): {}",
            self.runs,
            percent(self.confidence),
            if self.consistent() {
                "CONSISTENT"
            } else {
                "NOT CONSISTENT"
            }
        )?;
        writeln!(
            f,
            "{:<26} {:>6} {:>7}  {:<50} {:>8}  result",
            "check", "tests", "inside", "worst single test", "check p"
        )?;
        for c in &self.checks {
            let worst = c.worst.map_or_else(String::new, |w| {
                let inside = if w.lower <= w.value && w.value <= w.upper {
                    "∈"
                } else {
                    "∉"
                };
                format!(
                    "{}: {:.4} {inside} [{:.4}, {:.4}]",
                    w.location, w.value, w.lower, w.upper
                )
            });
            let result = match c.outcome {
                Outcome::Pass => "pass",
                Outcome::Fail => "FAIL",
                Outcome::NotRun => "not run",
            };
            writeln!(
                f,
                "{:<26} {:>6} {:>7}  {:<50} {:>8.2e}  {result}",
                c.check.name(),
                c.tests,
                c.inside,
                worst,
                c.p_value
            )?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Brute-force binomial CDF.
    fn cdf(t: usize, p: f64, k: usize) -> f64 {
        let mut c = 0.0;
        for j in 0..=k {
            let mut binom = 1.0;
            for i in 0..j {
                binom *= (t - i) as f64 / (i + 1) as f64;
            }
            c += binom * p.powi(j as i32) * (1.0 - p).powi((t - j) as i32);
        }
        c
    }

    #[test]
    fn binomial_cdf_matches_brute_force() {
        for &(t, g, k) in &[
            (100, 0.95, 88),
            (100, 0.95, 89),
            (10, 0.95, 7),
            (37, 0.9, 30),
        ] {
            let (a, b) = (binomial_cdf(k, t, g), cdf(t, g, k));
            assert!(
                (a - b).abs() < 1e-12 * b.max(1e-300),
                "{t} {g} {k}: {a} vs {b}"
            );
        }
        // P(X ≤ 88) = 0.0043, P(X ≤ 89) = 0.0115 for Binomial(100, 0.95).
        assert!((binomial_cdf(88, 100, 0.95) - 0.004274182466365944).abs() < 1e-12);
        assert_eq!(binomial_cdf(5, 5, 0.95), 1.0);
    }

    fn decide(rule: FamilyRule, p_values: &[f64]) -> CheckResult {
        let mut f = FamilyTest::new(Check::Nees, 0.95, rule).unwrap();
        for (i, &p) in p_values.iter().enumerate() {
            // value 0 inside [−1, 1] when p ≥ 0.05, else outside: as the bands would say.
            let v = if p >= 0.05 { 0.0 } else { 2.0 };
            f.add(Location::Slot { slot: i }, v, -1.0, 1.0, p);
        }
        f.finish()
    }

    #[test]
    fn simes_p_value() {
        // min(4·0.01/1, 4·0.02/2, 4·0.5/3, 4·0.9/4) = 0.04.
        let c = decide(FamilyRule::Simes, &[0.5, 0.02, 0.9, 0.01]);
        assert!((c.p_value - 0.04).abs() < 1e-15);
        assert_eq!(c.outcome, Outcome::Fail);
        assert_eq!(c.inside, 2);
        let c = decide(FamilyRule::Simes, &[0.5, 0.03, 0.9, 0.02]);
        assert!((c.p_value - 0.06).abs() < 1e-15);
        assert_eq!(c.outcome, Outcome::Pass);
        assert_eq!(decide(FamilyRule::Simes, &[]).outcome, Outcome::NotRun);
        // One gross outlier among many fails (Bonferroni part).
        let mut p = vec![0.5; 99];
        p.push(1e-5);
        assert_eq!(decide(FamilyRule::Simes, &p).outcome, Outcome::Fail);
    }

    #[test]
    fn binomial_rule() {
        let rule = FamilyRule::Binomial {
            test_confidence: 0.95,
        };
        // 100 tests, 12 outside at p = 0.04 each: P(X ≤ 88) = 0.0043, T p_min = 4:
        // p = 2 × 0.0043 < 0.05 → fail; 8 outside: P(X ≤ 92) ≈ 0.13 → pass.
        let mut p = vec![0.5; 88];
        p.extend([0.04; 12]);
        let c = decide(rule, &p);
        assert!((c.p_value - 2.0 * 0.004274182466365944).abs() < 1e-12);
        assert_eq!(c.outcome, Outcome::Fail);
        let mut p = vec![0.5; 92];
        p.extend([0.04; 8]);
        assert_eq!(decide(rule, &p).outcome, Outcome::Pass);
    }
}
