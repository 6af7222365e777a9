//! The `lu_noise_id` example's reproduction (`examples/reproductions/lu_noise_id.rs`): the
//! per-epoch model is exact (its likelihood equals the 200 Hz filter's), and on simulated data
//! with W = 0.0004 the estimates cover the truth and the likelihood ratio rejects W = 0.0016.

use crate::lu_noise_id::{NoiseIdConfig, epoch_model, epoch_record, run_identification};
use estim_core::nalgebra::Vector1;
use estim_filters::KalmanFilter;
use estim_filters::noise_id::likelihood::sequence_log_likelihood;
use estim_models::lu::{FilterSettings, LuFilter, Scenario, simulate};

#[test]
fn the_epoch_model_has_the_200_hz_filters_likelihood() {
    // Independent route: Lu's own 200 Hz filter (40 predictions per fix), summing the update
    // log-likelihoods, against the aggregated Φ⁴⁰, W·G model on the same record.
    let scenario = Scenario::paper().with_duration(60.0);
    let seed = 12;
    let sim = simulate(&scenario, seed).unwrap();
    let mut lu = LuFilter::new(&scenario, &FilterSettings::consistent(&scenario)).unwrap();
    let mut fixes = sim.gps.iter().peekable();
    let mut direct = 0.0;
    for (j, &a) in sim.accelerometer.iter().enumerate() {
        lu.propagate(a).unwrap();
        if let Some(&&(step, z)) = fixes.peek()
            && step == j + 1
        {
            fixes.next();
            direct += lu.update(&z).unwrap().log_likelihood;
        }
    }
    let model = epoch_model(
        &scenario,
        scenario.accel_noise_variance,
        (
            scenario.gps_position_variance,
            scenario.gps_velocity_variance,
        ),
    );
    let zs = epoch_record(&scenario, seed).unwrap();
    let inputs = vec![Vector1::zeros(); zs.len() - 1];
    let epoch = sequence_log_likelihood(
        &KalmanFilter::new(model.prior.clone()),
        &model.process,
        &inputs,
        1.0,
        &model.measurement,
        &zs,
    )
    .unwrap();
    // Same quantity by two summation orders of Φ (12 000 vs 300 steps): round-off only,
    // relative 1e-9 (the covariances have a condition number ~10⁵).
    assert!(
        (epoch - direct).abs() < 1e-9 * direct.abs(),
        "{epoch} vs {direct}"
    );
}

#[test]
fn recovers_w_and_rejects_the_listings_value() {
    let config = NoiseIdConfig {
        realizations: 2,
        ..NoiseIdConfig::quick()
    };
    let r = run_identification(&config).unwrap();
    assert!(r.em_monotone);
    let s = &config.scenario;
    let truth = [
        s.accel_noise_variance,
        s.gps_position_variance,
        s.gps_velocity_variance,
    ];
    for i in 0..3 {
        // 4 standard errors: a fixed seed, 99.99 % coverage if the estimate is Gaussian.
        assert!(
            (r.ml_values[i] - truth[i]).abs() < 4.0 * r.ml_standard_errors[i],
            "{i}: {} ± {} vs {}",
            r.ml_values[i],
            r.ml_standard_errors[i],
            truth[i]
        );
    }
    // The unconstrained maximum is at least the profile maximum at W = 0.0016.
    assert!(r.ml.log_likelihood >= r.printed_log_likelihood);
    // The χ²₁ 99 % point is 6.63: W = 0.0016 is rejected on these data.
    assert!(r.likelihood_ratio > 6.63, "{}", r.likelihood_ratio);
    assert!(r.p_value < 0.01);
}
