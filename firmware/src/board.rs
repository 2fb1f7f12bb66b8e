//! Bare-metal pieces shared by the board binaries: the model flash slots and
//! the panic handler. Only built for `target_os = "none"`.
#![allow(unsafe_code)]

use core::panic::PanicInfo;

unsafe extern "C" {
    static _model_a_start: u8;
    static _model_b_start: u8;
}

/// The MODEL_A flash slot (memory.x) as bytes.
pub fn model_slot_a() -> &'static [u8] {
    // SAFETY: memory.x reserves MODEL_SLOT_LEN bytes of flash at
    // `_model_a_start`; the program image never writes there.
    unsafe { core::slice::from_raw_parts(&raw const _model_a_start, crate::MODEL_SLOT_LEN) }
}

/// The MODEL_B flash slot (memory.x) as bytes.
pub fn model_slot_b() -> &'static [u8] {
    // SAFETY: as for MODEL_A, at `_model_b_start`.
    unsafe { core::slice::from_raw_parts(&raw const _model_b_start, crate::MODEL_SLOT_LEN) }
}

/// A panic is a bug: stop at a permanent undefined instruction so a debugger
/// (or QEMU) shows where; the watchdog of a real board resets it.
#[cfg(not(feature = "panic-free-check"))]
#[panic_handler]
fn panic(_: &PanicInfo) -> ! {
    cortex_m::asm::udf()
}

/// With `panic-free-check`, any panic path that survives optimisation makes
/// the link fail on this undefined symbol (src/bin/panic_free_check.rs).
#[cfg(feature = "panic-free-check")]
#[panic_handler]
fn panic(_: &PanicInfo) -> ! {
    unsafe extern "C" {
        fn hot_path_can_panic() -> !;
    }
    // SAFETY: never executed: the symbol is undefined, so an image in which
    // this call is reachable does not link.
    unsafe { hot_path_can_panic() }
}

unsafe extern "C" {
    static _stack_end: u32;
    static _stack_start: u32;
}

/// Pattern painted into the unused stack to find its high-water mark.
const PAINT: u32 = 0xDEAD_BEEF;
/// Bytes below the current stack pointer left unpainted (this function's frame).
const PAINT_MARGIN: usize = 256;

/// Paints the unused stack (below the current frame) with a known pattern.
/// Call first thing in `main`; [`stack_peak_bytes`] then reports the deepest use.
pub fn paint_stack() {
    let bottom = &raw const _stack_end as usize;
    let sp = cortex_m::register::msp::read() as usize;
    let mut addr = bottom;
    while addr + PAINT_MARGIN < sp {
        // SAFETY: [_stack_end, sp − margin) is the unused part of the stack
        // region cortex-m-rt reserves; nothing lives there yet.
        unsafe { core::ptr::write_volatile(addr as *mut u32, PAINT) };
        addr += 4;
    }
}

/// Deepest stack use since [`paint_stack`], bytes.
pub fn stack_peak_bytes() -> usize {
    let bottom = &raw const _stack_end as usize;
    let top = &raw const _stack_start as usize;
    let mut addr = bottom;
    // SAFETY: reads words of the stack region, which is always mapped RAM.
    while addr < top && unsafe { core::ptr::read_volatile(addr as *const u32) } == PAINT {
        addr += 4;
    }
    top - addr
}
