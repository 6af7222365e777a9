//! estim on a Cortex-M4F under QEMU (`docs/embedded.md`). Runs Lu's calibration filter in
//! `f32` over the recorded fixes and prints the final estimate and covariance as f32 bit
//! patterns (the host test `firmware` compares them with the host's run of the same code);
//! then measures the peak stack of one predict + update of each filter of [`shapes`] by
//! painting the free stack. Output over semihosting, one `key values…` line each; exits QEMU
//! with status 0, or 1 if anything failed.
#![no_std]
#![no_main]

use core::ptr::{addr_of, read_volatile, write_volatile};

use cortex_m_rt::entry;
use cortex_m_semihosting::{debug, hprintln};
use estim_core::Error;
use estim_core::nalgebra::{Vector2, Vector4};
use estim_firmware::{lu, shapes, table};

/// What unused stack is painted with.
const PAINT: u32 = 0xA5C3_5A3C;

unsafe extern "C" {
    /// cortex-m-rt's linker script: the first address after `.bss` and `.uninit`, the lowest
    /// the stack (which grows down from the end of RAM) may reach.
    static __sheap: u32;
}

#[entry]
fn main() -> ! {
    let status = match report() {
        Ok(()) => debug::EXIT_SUCCESS,
        Err(e) => {
            hprintln!("error {}", e);
            debug::EXIT_FAILURE
        }
    };
    debug::exit(status);
    #[allow(clippy::empty_loop)]
    loop {}
}

#[panic_handler]
fn panic(info: &core::panic::PanicInfo<'_>) -> ! {
    hprintln!("panic {}", info);
    debug::exit(debug::EXIT_FAILURE);
    #[allow(clippy::empty_loop)]
    loop {}
}

fn report() -> Result<(), Error> {
    let (x, p) = lu::run()?;
    hprintln!("fixes {}", table::FIXES.len());
    hprintln!(
        "x {:08x} {:08x} {:08x}",
        x[0].to_bits(),
        x[1].to_bits(),
        x[2].to_bits()
    );
    let p = p.transpose(); // column-major storage: rows of P in order
    let b = p.as_slice().iter().map(|v| v.to_bits());
    let mut row = [0u32; 9];
    for (r, bits) in row.iter_mut().zip(b) {
        *r = bits;
    }
    hprintln!(
        "P {:08x} {:08x} {:08x} {:08x} {:08x} {:08x} {:08x} {:08x} {:08x}",
        row[0],
        row[1],
        row[2],
        row[3],
        row[4],
        row[5],
        row[6],
        row[7],
        row[8]
    );

    let fix = table::FIXES[0];
    let (z2, z4) = (
        Vector2::from(fix),
        Vector4::new(fix[0], fix[1], fix[0], fix[1]),
    );
    let (process3, gps3, process6, gps6) = (
        shapes::process3(),
        shapes::gps3(),
        shapes::process6(),
        shapes::gps6(),
    );
    let mut ekf3 = shapes::ekf(shapes::prior3()?);
    let mut ukf3 = shapes::ukf(shapes::prior3()?);
    let mut ekf6 = shapes::ekf(shapes::prior6()?);
    let mut ukf6 = shapes::ukf(shapes::prior6()?);
    let mut srukf3 = shapes::srukf(shapes::prior3()?);
    let mut srukf6 = shapes::srukf(shapes::prior6()?);
    let mut result = Ok(());
    let peaks = [
        (
            "ekf3",
            peak_stack(|| result = result.and(shapes::step(&mut ekf3, &process3, &gps3, &z2))),
        ),
        (
            "ukf3",
            peak_stack(|| result = result.and(shapes::step(&mut ukf3, &process3, &gps3, &z2))),
        ),
        (
            "ekf6",
            peak_stack(|| result = result.and(shapes::step(&mut ekf6, &process6, &gps6, &z4))),
        ),
        (
            "ukf6",
            peak_stack(|| result = result.and(shapes::step(&mut ukf6, &process6, &gps6, &z4))),
        ),
        (
            "srukf3",
            peak_stack(|| result = result.and(shapes::step(&mut srukf3, &process3, &gps3, &z2))),
        ),
        (
            "srukf6",
            peak_stack(|| result = result.and(shapes::step(&mut srukf6, &process6, &gps6, &z4))),
        ),
    ];
    result?;
    for (name, bytes) in peaks {
        hprintln!("stack {} {}", name, bytes);
    }
    Ok(())
}

/// The peak stack, in bytes below this function's stack pointer, of `f` (which calls the
/// not-inlined [`shapes::step`], so the step's frames are below it): paints every word from
/// the end of `.bss` to just below the stack pointer, runs `f`, and finds the lowest word no
/// longer painted. Interrupts are off (none is enabled), so nothing else writes there.
#[inline(never)]
fn peak_stack(f: impl FnOnce()) -> usize {
    let sp = cortex_m::register::msp::read() as usize;
    // The painting loop below runs in this frame, which is above `sp`; 16 bytes of margin.
    let top = (sp - 16) & !3;
    let bottom = addr_of!(__sheap) as usize;
    // SAFETY: [bottom, top) is RAM that nothing owns: above the statics (`__sheap` is the end
    // of `.bss`/`.uninit`, no heap exists) and below the live stack. Word-aligned.
    unsafe {
        let mut a = bottom;
        while a < top {
            write_volatile(a as *mut u32, PAINT);
            a += 4;
        }
    }
    f();
    let mut lowest = top;
    let mut a = bottom;
    while a < top {
        // SAFETY: the same words, read back.
        if unsafe { read_volatile(a as *const u32) } != PAINT {
            lowest = a;
            break;
        }
        a += 4;
    }
    sp - lowest
}
