//! # A GPS/INS in estim
//!
//! A strapdown inertial navigator integrates the IMU (gyroscopes, accelerometers) and is
//! corrected by GNSS fixes. [`estim::models::nav`](crate::models::nav) has the pieces as
//! models: the 15-state error-state mechanisation [`Strapdown`](crate::models::nav::Strapdown)
//! (attitude, velocity and position in a local NED frame, gyro and accelerometer biases), the
//! GNSS, barometer, magnetometer and heading sensors, static alignment and WGS-84 gravity. The
//! filters, the fusion driver and the derivative checks take them as they take any model, so an
//! EKF becomes a UKF by changing one word. The `flight_ins` example runs this over a real
//! aerobatic flight (`cargo run --release --example flight_ins`) and compares it with the
//! autopilot's own EKF3.
//!
//! ## The steps
//!
//! 1. **Origin and noise.** An [`Origin`](crate::models::nav::Origin) (latitude, longitude,
//!    height) fixes the local frame and gravity. The IMU's noise densities come from its data
//!    sheet or the autopilot's parameters ([`InsSettings`](crate::models::nav::InsSettings);
//!    ArduPilot's `EK3_GYRO_P_NSE`, `EK3_ACC_P_NSE`, … are these densities).
//! 2. **Alignment.** At rest, the mean accelerometer reading gives roll and pitch and the
//!    magnetometer the heading ([`static_alignment`](crate::models::nav::static_alignment)).
//!    The mean gyro reading is the gyro bias (plus the earth rate, if you model it).
//! 3. **The filter on the attitude manifold.** The attitude block is a rotation: give the filter
//!    [`nav::state_space`](crate::models::nav::state_space), so ⊞ composes rotations
//!    (q ⊞ δθ = q ⊗ Exp(δθ)) and the covariance is that of the body-frame attitude error (the
//!    multiplicative EKF). The attitude lives in the filter's own state: snapshots, rollback
//!    and checkpoints carry it.
//! 4. **Time.** An IMU sample is the mean over the interval *before* its timestamp: in the
//!    [fusion driver](crate::filters::fusion) use
//!    [`InputConvention::Preceding`](crate::filters::fusion::InputConvention::Preceding). A GNSS
//!    fix is valid some 0.1–0.2 s before it arrives: fuse it at the time it was *taken*; the
//!    driver rolls the filter back and replays the IMU samples since (see
//!    [`sensor_fusion`](super::sensor_fusion)). On the flight log, fusing on arrival instead
//!    costs a factor 3–7 in accuracy (attitude median 0.66° → 1.91°, NE position 0.45 → 3.15 m).
//!
//! ## At rest, with position fixes
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
//! ## What the flight example adds
//!
//! - **Settings from the recording**: noise densities and the GPS delay from the log's
//!   parameters, the origin from its home position, nothing tuned to the one flight
//!   (`--data DIR` runs another log of the same kind).
//! - **GNSS velocity as well as position** ([`GnssVelocity`](crate::models::nav::GnssVelocity)),
//!   through one [`SensorSet`](crate::filters::fusion::SensorSet) enum, gated at 1 − 10⁻⁵ so only
//!   gross errors are refused.
//! - **No magnetometer in the filter**: in aerobatics its field direction scattered ±10–15°
//!   (motor currents); GPS velocity makes the heading observable once the vehicle moves. At rest,
//!   before take-off, the heading is as uncertain as the alignment left it (the whole log's
//!   attitude p95 of 17° comes from that phase).
//! - **Results** (airborne, against EKF3 core 0): attitude median 0.66°, p95 1.79°; NE position
//!   0.45 m and velocity 0.263 m/s RMS; the filter's own 3σ covers 97–100 % of the errors. EKF3's
//!   two cores differ from each other by 1.42° / 3.44°.
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
