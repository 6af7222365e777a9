//! estim's filters without std on a Cortex-M4F: the code the firmware binaries share.
//!
//! - [`table`]: one recorded realization of Lu's calibration scenario (generated on the host
//!   from estim-models' simulator; a host test keeps it in step).
//! - [`lu`]: Lu's error-state Kalman filter over that record, in `f32`.
//! - [`shapes`]: the 3-state and 6-state EKF and UKF whose footprint `docs/embedded.md` lists.
//!
//! The host test `firmware` of the `estim` package includes [`table`] and [`lu`] by path and
//! runs the same filter on the host, to compare with what the firmware prints.
#![no_std]
#![deny(missing_docs)]
#![forbid(unsafe_code)]

pub mod lu;
pub mod shapes;
pub mod table;

/// A filter-only firmware: `minimal!(filter, prior, process, gps, measurement)` runs one of
/// [`shapes`]' filters over the recorded fixes (one predict and one update per fix) and exits
/// QEMU with status 0, or 1 if a step fails. No output: its flash and RAM are the filter's,
/// the table's and the start-up code's (`docs/embedded.md`).
#[macro_export]
macro_rules! minimal {
    ($filter:ident, $prior:ident, $process:ident, $gps:ident, |$fix:ident| $z:expr) => {
        #[cortex_m_rt::entry]
        fn main() -> ! {
            let run = || -> Result<(), estim_core::Error> {
                use $crate::shapes;
                let mut filter = shapes::$filter(shapes::$prior()?);
                let (process, gps) = (shapes::$process(), shapes::$gps());
                for $fix in &$crate::table::FIXES {
                    shapes::step(&mut filter, &process, &gps, &$z)?;
                }
                Ok(())
            };
            let status = match run() {
                Ok(()) => cortex_m_semihosting::debug::EXIT_SUCCESS,
                Err(_) => cortex_m_semihosting::debug::EXIT_FAILURE,
            };
            cortex_m_semihosting::debug::exit(status);
            #[allow(clippy::empty_loop)]
            loop {}
        }

        #[panic_handler]
        fn panic(_: &core::panic::PanicInfo<'_>) -> ! {
            cortex_m_semihosting::debug::exit(cortex_m_semihosting::debug::EXIT_FAILURE);
            #[allow(clippy::empty_loop)]
            loop {}
        }
    };
}
