//! The board's interrupt and exception handlers and what they share with
//! the run loop: USART1's (bytes between the UART and the frame and
//! command queues), EXTI0's (data-ready stamps), SysTick's (the loop's
//! wake-up) and HardFault's (on a fresh stack: the cause recorded, a stack
//! overflow included, then a reset). What USART1's and EXTI0's do is
//! `crate::interrupts` (host-tested, and run by the fault campaign); here
//! they only fetch their state and wire the registers to it.
#![allow(unsafe_code)]

use core::sync::atomic::{AtomicPtr, AtomicU32, Ordering};

use cortex_m_rt::exception;
use heapless::spsc::{Consumer, Producer};
use stm32f4xx_hal::gpio::{ExtiPin, Input, PB0};
use stm32f4xx_hal::pac::{self, interrupt};
use stm32f4xx_hal::serial::{Rx, Tx, TxListen};

#[cfg(not(feature = "board-qemu"))]
use super::chip as platform;
use super::hw;
#[cfg(feature = "board-qemu")]
use super::qemu as platform;
use crate::interrupts::{self, Transmit};

/// USART1's halves and the queue ends its interrupt serves.
pub(super) struct UartIsr {
    pub(super) tx: Tx<pac::USART1>,
    pub(super) rx: Rx<pac::USART1>,
    pub(super) outgoing: Consumer<'static, u8>,
    pub(super) incoming: Producer<'static, u8>,
}

/// The data-ready pin and the stamp queue its interrupt fills.
pub(super) struct DataReadyIsr {
    pub(super) pin: PB0<Input>,
    pub(super) stamps: Producer<'static, u32>,
}

/// USART1's halves and queue ends, once setup has handed them over
/// ([`hand_over`]); only the USART1 handler reaches them, so it takes no
/// critical section (which would hold EXTI0 off and jitter its stamps).
static UART: AtomicPtr<UartIsr> = AtomicPtr::new(core::ptr::null_mut());
/// The data-ready pin and stamp queue, once setup has handed them over;
/// only the EXTI0 handler reaches them.
static DATA_READY: AtomicPtr<DataReadyIsr> = AtomicPtr::new(core::ptr::null_mut());

/// Hands the handlers their state (from `singleton!`s: nothing else keeps
/// a reference); before their interrupts are unmasked.
pub(super) fn hand_over(uart: &'static mut UartIsr, data_ready: &'static mut DataReadyIsr) {
    UART.store(uart, Ordering::Release);
    DATA_READY.store(data_ready, Ordering::Release);
}

/// The state `cell` was handed, for the one handler that owns it.
///
/// # Safety
/// Called only from that handler (which never preempts itself), and the
/// reference not kept past its return.
unsafe fn owned<T>(cell: &AtomicPtr<T>) -> Option<&'static mut T> {
    // SAFETY: a `&'static mut` from `hand_over`, no other reference kept,
    // dereferenced by its one handler alone (the caller's promise).
    unsafe { cell.load(Ordering::Acquire).as_mut() }
}
/// Command bytes lost: the UART overran or the receive queue was full.
pub(super) static RX_OVERRUNS: AtomicU32 = AtomicU32::new(0);
/// Data-ready stamps lost to a full stamp queue (the edge count still includes them).
pub(super) static STAMP_OVERRUNS: AtomicU32 = AtomicU32::new(0);

// The HardFault vector: onto a fresh stack before anything is pushed
// (after a stack overflow the faulting SP lies below RAM, and a handler
// whose first instruction pushes there would lock the core up until the
// watchdog fires), then the Rust handler with the faulting SP. Defining
// `HardFault` here replaces cortex-m-rt's default (its `PROVIDE`).
core::arch::global_asm!(
    ".section .HardFault.user,\"ax\"",
    ".global HardFault",
    ".type HardFault,%function",
    ".thumb_func",
    "HardFault:",
    "    mrs r0, msp",
    "    ldr r1, =_stack_start",
    "    msr msp, r1",
    "    b {handler}",
    // Its size in the symbol table: `cargo xtask check-board-panics` walks
    // the image's functions from it.
    ".size HardFault, . - HardFault",
    handler = sym hard_fault_on_fresh_stack,
);

/// Records the HardFault (crate::fault::hard_fault_record: the frame's PC
/// and LR, or the overflow) and resets; runs on the fresh stack the vector
/// above gave it.
unsafe extern "C" fn hard_fault_on_fresh_stack(faulting_sp: u32) -> ! {
    let (bottom, top) = super::stack_bounds();
    // SAFETY: `hard_fault_record` reads only whole frames inside the stack region, mapped RAM.
    let record = crate::fault::hard_fault_record(faulting_sp, bottom, top, |addr| unsafe {
        core::ptr::read_volatile(addr as *const u32)
    });
    super::store_fault(record);
    cortex_m::peripheral::SCB::sys_reset()
}

/// Wakes the main loop every millisecond, so that a silent data-ready
/// line is noticed (crate::pacing synthesises the steps).
#[exception]
fn SysTick() {}

#[interrupt]
fn USART1() {
    // SAFETY: USART1's own state, in USART1's handler.
    let Some(u) = (unsafe { owned(&UART) }) else { return };
    match interrupts::serve_uart(&mut u.rx, &mut u.tx, &mut u.outgoing, &mut u.incoming, &RX_OVERRUNS) {
        Transmit::Sending => platform::pend_tx(),
        Transmit::Idle => u.tx.unlisten(),
    }
}

#[interrupt]
fn EXTI0() {
    let stamp = hw::Tim2Clock::now();
    // SAFETY: EXTI0's own state, in EXTI0's handler.
    if let Some(d) = unsafe { owned(&DATA_READY) } {
        d.pin.clear_interrupt_pending_bit();
        interrupts::stamp_data_ready(stamp, &mut d.stamps, &STAMP_OVERRUNS);
    }
}

/// Starts the transmit interrupt after a frame was queued (from the main
/// loop: USART1's handler only ever stops it, when the queue is empty).
pub(super) fn start_tx() {
    hw::usart1_listen_tx();
    platform::pend_tx();
}
