//! Bare-metal pieces of every image (the board's and the QEMU test images): the model flash slots and
//! the panic handler. Only built for `target_os = "none"`.
#![allow(unsafe_code)]

use core::panic::PanicInfo;
use core::sync::atomic::{AtomicU32, Ordering};

// Copies the tables memory.x keeps in RAM (`.ram_tables`: rbf-core's exp2
// octave table) from their load address in flash, before RAM is initialised
// and before main. Assembly, as cortex-m-rt asks of a pre-init: no Rust code
// may run before RAM is set up.
core::arch::global_asm!(
    ".section .text.__pre_init,\"ax\"",
    ".global __pre_init",
    ".type __pre_init,%function",
    ".thumb_func",
    "__pre_init:",
    "    ldr r0, =__sram_tables",
    "    ldr r1, =__eram_tables",
    "    ldr r2, =__siram_tables",
    "1:  cmp r1, r0",
    "    beq 2f",
    "    ldm r2!, {{r3}}",
    "    stm r0!, {{r3}}",
    "    b 1b",
    "2:  bx lr",
);

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

/// The fault record ([`crate::fault`]): words the runtime never
/// initialises (`.uninit`), so they survive a reset.
#[unsafe(link_section = ".uninit.FAULT_RECORD")]
static FAULT_RECORD: [AtomicU32; crate::fault::RECORD_WORDS] =
    [const { AtomicU32::new(0) }; crate::fault::RECORD_WORDS];

fn store_fault_words(words: [u32; crate::fault::RECORD_WORDS]) {
    for (cell, w) in FAULT_RECORD.iter().zip(words) {
        cell.store(w, Ordering::SeqCst);
    }
}

/// Stores `record` for the next boot (call from a fault handler, then reset).
pub fn store_fault(record: crate::fault::FaultRecord) {
    store_fault_words(record.to_words());
}

/// The record a fault handler left before the last reset, if any; clears it.
pub fn take_fault() -> Option<crate::fault::FaultRecord> {
    let mut words = [0u32; crate::fault::RECORD_WORDS];
    for (w, cell) in words.iter_mut().zip(&FAULT_RECORD) {
        *w = cell.load(Ordering::SeqCst);
    }
    store_fault_words([0; crate::fault::RECORD_WORDS]);
    crate::fault::FaultRecord::from_words(words)
}

/// A panic is a bug (the panic-free check proves none reachable after
/// init). On the gyro board: record it with the handler's return address
/// and reset; the next boot reports it (firmware::fault).
#[cfg(all(not(feature = "panic-free-check"), feature = "board-stm32f405"))]
#[panic_handler]
fn panic(_: &PanicInfo) -> ! {
    let return_address = cortex_m::register::lr::read();
    store_fault(crate::fault::FaultRecord {
        reason: crate::fault::FaultReason::Panic,
        pc: return_address,
        lr: return_address,
    });
    cortex_m::peripheral::SCB::sys_reset()
}

/// A panic is a bug: on the QEMU boards stop at a permanent undefined
/// instruction, so that the run fails where it happened.
#[cfg(all(not(feature = "panic-free-check"), not(feature = "board-stm32f405")))]
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

/// The stack region, `(bottom, top)` addresses (it grows down from `top`).
pub fn stack_bounds() -> (u32, u32) {
    (&raw const _stack_end as u32, &raw const _stack_start as u32)
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
