//! # Runtime sizes
//!
//! The same filters run on `DVector<f64>`/`DMatrix<f64>` when the state's size is known only at
//! run time: change the types, nothing else. Static sizes (`SVector<f64, 6>`) are fastest for
//! small states (n ≤ 6); from n ≈ 12 both are within 10 % of each other (BENCHMARKS.md, "Static
//! or dynamic").
//!
//! ```
//! use estim::prelude::*;
//! use estim::nalgebra::{DMatrix, DVector};
//!
//! let n = 8; // from a configuration file, say
//! let process = LinearProcess {
//!     transition: DMatrix::<f64>::identity(n, n),
//!     input: DMatrix::zeros(n, 0),
//!     noise: DMatrix::identity(n, n) * 1e-3,
//! };
//! let sensor = LinearMeasurement {
//!     observation: DMatrix::<f64>::identity(n, n),
//!     noise: DMatrix::identity(n, n) * 0.1,
//! };
//! let mut kf = KalmanFilter::new(Gaussian::new(DVector::zeros(n), DMatrix::identity(n, n))?);
//! // Size the filter's buffers once: from here on no step allocates.
//! kf.prepare_predict(&process, &DVector::zeros(0), 1.0)?;
//! let mut report = UpdateReport::zeros(estim::nalgebra::Dyn(n));
//! kf.prepare_update(&sensor, &mut report)?;
//! for _ in 0..10 {
//!     kf.predict(&process, &DVector::zeros(0), 1.0)?;
//!     kf.update_into(&sensor, &DVector::from_element(n, 1.0), &mut report)?;
//! }
//! assert!((kf.state()[n - 1] - 1.0).abs() < 0.1);
//! # Ok::<(), estim::core::Error>(())
//! ```
//!
//! A static-size prior moves to runtime sizes with
//! [`Gaussian::into_dyn`](crate::core::Gaussian::into_dyn). A model of your own runs
//! allocation-free when it implements [`InPlace`](crate::core::InPlace) (its value, noise and
//! derivatives written into the filter's buffers) and returns `Some(self)` from its `in_place`
//! method, as the linear models do (its residual is written in place by every model).
