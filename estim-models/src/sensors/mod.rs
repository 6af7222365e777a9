//! Sensor models: position, range, bearing, range-bearing.
//!
//! Each reads the position from the **first components** of the state, which is where every
//! model of [`motion`](crate::motion) keeps it, so one sensor serves any of them (and any user
//! state laid out the same way): generic over the state size N (a `Const`), static sizes.
//!
//! | sensor | z | derivatives |
//! |---|---|---|
//! | [`Position<T, D>`] | p (D components) | linear, `None` Hessians |
//! | [`Range<T, D>`] | ‖p − o‖ (D = 2 or 3) | Jacobian, Hessian |
//! | [`Bearing`] | atan2(p_y − o_y, p_x − o_x), wrapped residual | Jacobian, Hessians |
//! | [`RangeBearing`] | (range, bearing) | Jacobian, Hessians |
//!
//! o is the sensor's (or beacon's) known position. At p = o the range is not differentiable
//! and the bearing not defined: the Jacobian and Hessians returned there are zero (finite; the
//! update then draws no information from that reading) rather than NaN.

mod geometry;

pub use geometry::{Bearing, Position, Range, RangeBearing};
