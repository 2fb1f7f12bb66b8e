//! Bare-metal pieces shared by the board binaries: the model flash slots and
//! the panic handler. Only built for `target_os = "none"`.
#![allow(unsafe_code)]

use core::panic::PanicInfo;

unsafe extern "C" {
    static _model_a_start: u8;
}

/// The MODEL_A flash slot (memory.x) as bytes.
pub fn model_slot_a() -> &'static [u8] {
    // SAFETY: memory.x reserves MODEL_SLOT_LEN bytes of flash at
    // `_model_a_start`; the program image never writes there.
    unsafe { core::slice::from_raw_parts(&raw const _model_a_start, crate::MODEL_SLOT_LEN) }
}

/// A panic is a bug: stop at a permanent undefined instruction so a debugger
/// (or QEMU) shows where; the watchdog of a real board resets it.
#[panic_handler]
fn panic(_: &PanicInfo) -> ! {
    cortex_m::asm::udf()
}
