//! # A GPS/INS in estim
//!
//! A strapdown inertial navigator corrected by GNSS, set up the way the repository's
//! `flight_ins` example runs it over a real ArduPilot flight (`cargo run --release --example
//! flight_ins`; its body is `examples/reproductions/flight_ins/`). The models are
//! [`estim::models::nav`](crate::models::nav); the filter is any of the family on the nav
//! state space; the fusion driver ([`estim::filters::fusion`](crate::filters::fusion)) puts
//! each IMU sample and each fix at its own time.
//!
//! 1. **The frame**: an [`Origin`](crate::models::nav::Origin) (geodetic latitude, longitude,
//!    height: the autopilot's home, else the first fix). Positions are NED metres about it
//!    ([`Origin::ned`](crate::models::nav::Origin::ned) converts a fix), gravity is the WGS-84
//!    normal gravity there.
//! 2. **The state**: 15 components, attitude error, velocity, position, gyro and accelerometer
//!    biases ([`ATTITUDE`](crate::models::nav::ATTITUDE) … ), on the state space
//!    [`state_space()`](crate::models::nav::state_space): the attitude composes on the
//!    quaternion manifold, so the covariance is that of the body-frame attitude error, and the
//!    attitude lives in the filter's own state (the driver's replays restore it).
//! 3. **The start**: [`static_alignment`](crate::models::nav::static_alignment) levels the
//!    vehicle from the mean accelerometer reading at rest and sets the heading from the
//!    magnetometer and the field's direction; the mean gyro reading at rest is the first gyro
//!    bias. The prior covariance says how well that is known (degrees of roll and pitch, tens
//!    of degrees of heading from a disturbed compass).
//! 4. **The process**: [`Strapdown`](crate::models::nav::Strapdown) with the IMU's noise
//!    densities ([`InsSettings`](crate::models::nav::InsSettings); `flight_ins` reads them from
//!    the autopilot's own parameters, which are per-step σ at the autopilot's filter step Δt:
//!    the density is σ √Δt), its input an [`Imu`](crate::models::nav::Imu) sample.
//!    An IMU sample is the mean over the interval *before* its time: tell the driver so with
//!    [`InputConvention::Preceding`](crate::filters::fusion::InputConvention::Preceding)
//!    (each span is predicted with the sample that covers it, not with the one before).
//! 5. **The sensors**: [`GnssPosition`](crate::models::nav::GnssPosition) and
//!    [`GnssVelocity`](crate::models::nav::GnssVelocity) (also `BaroHeight`, `Magnetometer`,
//!    `Heading`) as one [`SensorSet`](crate::filters::fusion::SensorSet). A receiver reports a
//!    fix after it was taken (0.1-0.2 s for a u-blox): fuse it at the time it was *taken*; the
//!    driver rolls the filter back and replays the IMU samples since. On the vendored flight
//!    that is the difference between 0.40 m and 2.89 m of NE position error against the
//!    autopilot's EKF3. An unknown latency can be estimated from the recording: run the
//!    filter at a few candidate latencies and keep the one whose fixes are likeliest
//!    ([`FusionDriver::log_likelihood`](crate::filters::fusion::FusionDriver::log_likelihood),
//!    Σ log N(ν; 0, S)); `flight_ins` does so and finds 0.14 s.
//!
//! A vehicle at rest, level, heading north, 1 s of 50 Hz IMU samples and one fix taken
//! 0.15 s before it arrives:
//!
//! ```
//! use estim::prelude::*;
//! use estim::filters::fusion::InputConvention;
//! use estim::models::nav::{
//!     ATTITUDE, GYRO_BIAS, GnssPosition, Imu, InsSettings, Origin, POSITION, Strapdown,
//!     attitude, state_space, static_alignment,
//! };
//! use estim::nalgebra::{Const, Matrix3, SMatrix, SVector, Vector3};
//!
//! // 1. The frame, and what a level IMU at rest reads there.
//! let origin = Origin::from_degrees(51.642, -2.526, 100.0)?;
//! let g = origin.gravity(0.0);
//! let gyro_bias = Vector3::new(0.002, -0.001, 0.0005);
//! let at_rest = Imu { gyro: gyro_bias, accel: Vector3::new(0.0, 0.0, -g) };
//!
//! // 3. The start: level from the accelerometer, heading from a field pointing north and down.
//! let field = Vector3::new(0.19, 0.0, 0.45);
//! let q0 = static_alignment(&at_rest.accel, &field, &field)?;
//! let mut x = SVector::<f64, 15>::zeros();
//! x.fixed_rows_mut::<3>(ATTITUDE).copy_from(&estim::core::manifold::so3_log(&q0));
//! x.fixed_rows_mut::<3>(GYRO_BIAS).copy_from(&at_rest.gyro);
//! // σ: attitude 3° (heading 10°), 0.5 m/s, 2 m, gyro bias 3 mrad/s, accelerometer bias 0.3 m/s².
//! let sd = [0.05, 0.05, 0.17, 0.5, 0.5, 0.5, 2.0, 2.0, 2.0, 3e-3, 3e-3, 3e-3, 0.3, 0.3, 0.3];
//! let p = SMatrix::<f64, 15, 15>::from_diagonal(&SVector::from_fn(|i, _| sd[i] * sd[i]));
//! let filter = Ekf::new(Gaussian::new(x, p)?).with_state_space(state_space());
//!
//! // 5. One sensor: the GNSS position, 0.5 m horizontally, 1 m vertically.
//! struct Gnss(GnssPosition);
//! impl<F: Update<f64, Const<15>, Const<3>, GnssPosition>> SensorSet<f64, Const<15>, F> for Gnss {
//!     type Reading = Vector3<f64>;
//!     fn count(&self) -> usize { 1 }
//!     fn sensor(&self, _: &Vector3<f64>) -> usize { 0 }
//!     fn dimension(&self, _: usize) -> usize { 3 }
//!     fn update(&self, f: &mut F, z: &Vector3<f64>) -> estim::core::error::Result<Innovation<f64>> {
//!         f.update(&self.0, z).map(|r| Innovation::of(&r))
//!     }
//! }
//! let gnss = Gnss(GnssPosition { noise: Matrix3::from_diagonal(&Vector3::new(0.25, 0.25, 1.0)) });
//!
//! // 4. The process and the driver: IMU samples cover the interval before them; steps of at
//! // most 1.25 IMU periods; a history reaching back over the GPS latency.
//! let ins = Strapdown::new(origin, InsSettings::default())?;
//! let settings = FusionSettings { horizon: 0.5, max_step: 0.025, ..FusionSettings::default() };
//! let mut driver = FusionDriver::new(filter, ins, Imu::default(), gnss, 0.0, settings, SensorSettings::gated(0.99999))?
//!     .with_input_convention(InputConvention::Preceding)?;
//! for k in 1..=50 {
//!     let t = 0.02 * k as f64;
//!     driver.set_input(t, at_rest)?;
//!     if k == 40 {
//!         // A fix at the origin arrives at 0.8 s; it was taken at 0.65 s.
//!         assert!(driver.fuse(0.65, origin.ned(51.642, -2.526, 100.0))?.outcome.applied());
//!     }
//! }
//! let x = driver.filter().state();
//! // Still at the origin, still level and facing north.
//! assert!(x.fixed_rows::<3>(POSITION).norm() < 0.05);
//! assert!(attitude(x).angle_to(&q0) < 1e-3);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
//!
//! What `flight_ins` adds over this: the recording's parameters (noise densities, GPS latency,
//! declination) read from the log, both position and velocity fixes, the UKF beside the EKF
//! (one constructor changed), and the comparison with the autopilot's EKF3 (attitude against
//! its quaternion, NE position and velocity against its output, each filter's 3σ coverage).
//! The range-only counterpart, `plaza_range`, uses the planar models of
//! [`estim::models::motion`](crate::models::motion) and
//! [`augment`](crate::models::augment) instead.
//!
//! ## What is observable at rest
//!
//! A vehicle standing level, heading 30°, with a GNSS position fix every 0.2 s for 20 s. A tilt
//! error δθ turns gravity into a horizontal acceleration g δθ, which the position fixes see;
//! but an accelerometer bias b does the same, so at rest only g δθ + b is observable. With
//! prior σ_θ and σ_b, knowing g δθ + b exactly leaves tilt a variance of
//! σ_θ² σ_b² / (g² σ_θ² + σ_b²): the floor roll and pitch approach and cannot beat. The heading
//! is not observable at all (no motion, no magnetometer update), so its variance does not
//! shrink. That is what an INS at rest should say about itself:
//!
//! ```
//! use estim::prelude::*;
//! use estim::core::manifold::so3_log;
//! use estim::models::nav::{
//!     self, GnssPosition, Imu, InsSettings, Origin, Strapdown, normal_gravity, static_alignment,
//! };
//! use estim::nalgebra::{Matrix3, SMatrix, SVector, UnitQuaternion, Vector3};
//!
//! let origin = Origin::from_degrees(51.642, -2.526, 100.0)?;
//! // A good IMU: angle random walk 10⁻⁴ rad/s/√Hz (0.34°/√h), velocity random walk
//! // 0.01 m/s²/√Hz; no earth or transport rate. (With the autopilot-style defaults, 0.015 and
//! // 0.35, the gyro noise alone adds 0.9° of tilt σ a second and hides the floor below.)
//! let settings = InsSettings { gyro_noise: 1e-4, accel_noise: 0.01, ..InsSettings::default() };
//! let ins = Strapdown::new(origin, settings)?;
//! let g = normal_gravity(origin.latitude(), origin.height());
//!
//! // The truth and what a perfect IMU and magnetometer read at rest (body frame FRD).
//! let truth = UnitQuaternion::from_euler_angles(0.0, 0.0, 30f64.to_radians());
//! let field = Vector3::new(0.19, -0.005, 0.45); // the earth field in NED (any unit)
//! let imu = Imu { gyro: Vector3::zeros(), accel: truth.inverse() * Vector3::new(0.0, 0.0, -g) };
//! let q0 = static_alignment(&imu.accel, &(truth.inverse() * field), &field)?;
//!
//! // The prior: the aligned attitude, at rest at the origin. σ: 3° roll/pitch, 10° heading,
//! // 0.1 m/s, 1 m, gyro bias 1 mrad/s, accelerometer bias 0.1 m/s².
//! let mut x = SVector::<f64, 15>::zeros();
//! x.fixed_rows_mut::<3>(nav::ATTITUDE).copy_from(&so3_log(&q0));
//! let sd = [0.05, 0.05, 0.17, 0.1, 0.1, 0.1, 1.0, 1.0, 1.0, 1e-3, 1e-3, 1e-3, 0.1, 0.1, 0.1];
//! let p = SMatrix::<f64, 15, 15>::from_diagonal(&SVector::from_fn(|i, _| sd[i] * sd[i]));
//! let mut ekf = Ekf::new(Gaussian::new(x, p)?).with_state_space(nav::state_space());
//! // let mut ukf = Ukf::new(...).with_state_space(nav::state_space()); // the one-line swap
//!
//! let gnss = GnssPosition { noise: Matrix3::identity() * 0.5f64.powi(2) };
//! for k in 1..=2000 {
//!     ekf.predict(&ins, &imu, 0.01)?; // 100 Hz
//!     if k % 20 == 0 {
//!         ekf.update(&gnss, &Vector3::zeros())?;
//!     }
//! }
//! let (x, p) = (ekf.state(), ekf.covariance());
//! // The IMU is perfect, so the estimate stays where the alignment put it: the attitude
//! // (computed and compared through the quaternion) to round-off, velocity and position ≈ 0.
//! assert!(nav::attitude(x).angle_to(&truth) < 1e-9);
//! assert!(x.fixed_rows::<6>(nav::VELOCITY).norm() < 1e-9);
//! // Roll and pitch: σ 2.9° → near the floor σ_θ σ_b / √(g² σ_θ² + σ_b²) = 0.57°, never below.
//! let deg = |i: usize| p[(i, i)].sqrt().to_degrees();
//! let floor = (0.05 * 0.1 / (g * g * 0.05 * 0.05 + 0.1 * 0.1f64).sqrt()).to_degrees();
//! for tilt in [deg(0), deg(1)] {
//!     assert!(tilt > floor && tilt < 1.5 * floor, "tilt σ {tilt}° against the floor {floor}°");
//! }
//! // Heading: no information, so its σ is the prior's 10° or more (the gyro noise adds to it).
//! assert!(deg(2) >= 0.17f64.to_degrees() * 0.999, "heading {}", deg(2));
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
//!
//! ## Checking your own navigation model
//!
//! The Jacobians of a model on a manifold are checked on that manifold:
//! [`check_process_jacobian_on`](crate::core::derivative::check_process_jacobian_on) takes the
//! state space (a plain finite difference would compare against the wrong derivative). The
//! rotation helpers ([`so3_exp`](crate::core::manifold::so3_exp),
//! [`so3_log`](crate::core::manifold::so3_log)) are generic over the automatic-derivative
//! scalar, so [`AutoDiff`](crate::core::autodiff::AutoDiff) can derive the Jacobian of a
//! mechanisation you write yourself (see [`writing_a_model`](super::writing_a_model)).
