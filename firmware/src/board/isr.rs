//! The board's interrupt and exception handlers and what they share with
//! the run loop: USART1's (bytes between the UART and the frame and
//! command queues), EXTI0's (data-ready stamps), SysTick's (the loop's
//! wake-up) and HardFault's (the cause recorded, then a reset).
#![allow(unsafe_code)]

use core::cell::RefCell;
use core::sync::atomic::{AtomicU32, Ordering};

use cortex_m::interrupt::Mutex;
use cortex_m_rt::{ExceptionFrame, exception};
use heapless::spsc::{Consumer, Producer};
use stm32f4xx_hal::gpio::{ExtiPin, Input, PB0};
use stm32f4xx_hal::pac::{self, interrupt};
use stm32f4xx_hal::prelude::*;
use stm32f4xx_hal::serial::{Rx, Tx, TxListen};

#[cfg(not(feature = "board-qemu"))]
use super::chip as platform;
use super::hw;
#[cfg(feature = "board-qemu")]
use super::qemu as platform;
use crate::fault::{FaultReason, FaultRecord};
use crate::uart;

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

/// USART1's halves and queue ends, once setup has handed them over.
pub(super) static UART: Mutex<RefCell<Option<UartIsr>>> = Mutex::new(RefCell::new(None));
/// The data-ready pin and stamp queue, once setup has handed them over.
pub(super) static DATA_READY: Mutex<RefCell<Option<DataReadyIsr>>> = Mutex::new(RefCell::new(None));
/// Command bytes lost: the UART overran or the receive queue was full.
pub(super) static RX_OVERRUNS: AtomicU32 = AtomicU32::new(0);
/// Data-ready stamps lost to a full stamp queue (the edge count still includes them).
pub(super) static STAMP_OVERRUNS: AtomicU32 = AtomicU32::new(0);

#[exception]
unsafe fn HardFault(frame: &ExceptionFrame) -> ! {
    super::store_fault(FaultRecord {
        reason: FaultReason::HardFault,
        pc: frame.pc(),
        lr: frame.lr(),
    });
    cortex_m::peripheral::SCB::sys_reset()
}

/// Wakes the main loop every millisecond, so that a silent data-ready
/// line is noticed (crate::pacing synthesises the steps).
#[exception]
fn SysTick() {}

#[interrupt]
fn USART1() {
    cortex_m::interrupt::free(|cs| {
        // `try_borrow_mut`: a critical section on one core cannot find
        // the cell borrowed, and this way no panic path is linked.
        let Ok(mut uart) = UART.borrow(cs).try_borrow_mut() else {
            return;
        };
        let Some(u) = uart.as_mut() else { return };
        // The byte the receiver holds (an error read clears its flag;
        // bounded, so a line full of errors cannot hold the handler).
        for _ in 0..4 {
            match u.rx.read() {
                Ok(byte) => {
                    if uart::enqueue(&mut u.incoming, byte).is_err() {
                        RX_OVERRUNS.fetch_add(1, Ordering::Relaxed);
                    }
                }
                Err(stm32f4xx_hal::nb::Error::WouldBlock) => break,
                Err(stm32f4xx_hal::nb::Error::Other(_)) => {
                    RX_OVERRUNS.fetch_add(1, Ordering::Relaxed);
                }
            }
        }
        match u.outgoing.peek().copied() {
            Some(byte) => {
                if u.tx.write(byte).is_ok() {
                    let _ = uart::dequeue(&mut u.outgoing);
                }
                platform::pend_tx();
            }
            None => u.tx.unlisten(),
        }
    });
}

#[interrupt]
fn EXTI0() {
    let stamp = hw::Tim2Clock::now();
    cortex_m::interrupt::free(|cs| {
        if let Some(d) = DATA_READY
            .borrow(cs)
            .try_borrow_mut()
            .ok()
            .as_deref_mut()
            .and_then(Option::as_mut)
        {
            d.pin.clear_interrupt_pending_bit();
            if uart::enqueue(&mut d.stamps, stamp).is_err() {
                STAMP_OVERRUNS.fetch_add(1, Ordering::Relaxed);
            }
        }
    });
}

/// Starts the transmit interrupt after a frame was queued.
pub(super) fn start_tx() {
    cortex_m::interrupt::free(|cs| {
        if let Some(u) = UART
            .borrow(cs)
            .try_borrow_mut()
            .ok()
            .as_deref_mut()
            .and_then(Option::as_mut)
        {
            u.tx.listen();
        }
    });
    platform::pend_tx();
}
