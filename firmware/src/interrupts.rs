//! What the board's interrupt handlers do, written over embedded-hal-nb's
//! serial traits and the queues they share with the loop, so that the host
//! runs the very code the handlers run (`board::isr` only fetches the
//! handlers' state and wires the registers to it; the fault campaign,
//! `firmware-harness/tests/board_faults`, drives it with a simulated UART):
//!
//! - [`serve_uart`]: USART1's handler, bytes between the UART and the
//!   command and frame queues;
//! - [`stamp_data_ready`]: EXTI0's handler, a data-ready edge's TIM2 stamp
//!   into the stamp queue.

use core::sync::atomic::{AtomicU32, Ordering};

use embedded_hal_nb::nb;
use embedded_hal_nb::serial::{Read, Write};
use heapless::spsc::{Consumer, Producer};

use crate::uart;

/// Bytes the receive side takes per interrupt at most: a line full of
/// errors (each read clears one) cannot hold the handler.
pub const RX_READS_PER_INTERRUPT: usize = 4;

/// What the transmitter needs after [`serve_uart`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Transmit {
    /// Bytes are waiting: keep its interrupt on.
    Sending,
    /// The frame queue is empty: its interrupt can stop.
    Idle,
}

/// One USART interrupt: the bytes the receiver holds into `incoming`
/// (a receive error, or a byte the full queue cannot take, counts in
/// `rx_overruns`), then the next byte of `outgoing` to the transmitter if
/// it takes one (dequeued only once written). Never waits.
pub fn serve_uart<R: Read<u8>, T: Write<u8>>(
    rx: &mut R,
    tx: &mut T,
    outgoing: &mut Consumer<'_, u8>,
    incoming: &mut Producer<'_, u8>,
    rx_overruns: &AtomicU32,
) -> Transmit {
    for _ in 0..RX_READS_PER_INTERRUPT {
        match rx.read() {
            Ok(byte) => {
                if uart::enqueue(incoming, byte).is_err() {
                    rx_overruns.fetch_add(1, Ordering::Relaxed);
                }
            }
            Err(nb::Error::WouldBlock) => break,
            Err(nb::Error::Other(_)) => {
                rx_overruns.fetch_add(1, Ordering::Relaxed);
            }
        }
    }
    match outgoing.peek().copied() {
        Some(byte) => {
            if tx.write(byte).is_ok() {
                let _ = uart::dequeue(outgoing);
            }
            Transmit::Sending
        }
        None => Transmit::Idle,
    }
}

/// One data-ready edge: its timer `stamp` into `stamps`; a full queue
/// loses it and counts in `overruns` (the loop's edge count still sees it).
#[inline(always)]
pub fn stamp_data_ready(stamp: u32, stamps: &mut Producer<'_, u32>, overruns: &AtomicU32) {
    if uart::enqueue(stamps, stamp).is_err() {
        overruns.fetch_add(1, Ordering::Relaxed);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use heapless::spsc::Queue;

    type SerialError = embedded_hal_nb::serial::ErrorKind;

    /// A receiver with scripted results.
    struct Receiver(std::collections::VecDeque<nb::Result<u8, SerialError>>);

    /// A transmitter that takes a byte every other call.
    struct Transmitter {
        sent: Vec<u8>,
        busy: bool,
    }

    impl embedded_hal_nb::serial::ErrorType for Receiver {
        type Error = SerialError;
    }

    impl embedded_hal_nb::serial::ErrorType for Transmitter {
        type Error = SerialError;
    }

    impl Read<u8> for Receiver {
        fn read(&mut self) -> nb::Result<u8, SerialError> {
            self.0.pop_front().unwrap_or(Err(nb::Error::WouldBlock))
        }
    }

    impl Write<u8> for Transmitter {
        fn write(&mut self, byte: u8) -> nb::Result<(), SerialError> {
            self.busy = !self.busy;
            if self.busy {
                return Err(nb::Error::WouldBlock);
            }
            self.sent.push(byte);
            Ok(())
        }
        fn flush(&mut self) -> nb::Result<(), SerialError> {
            Ok(())
        }
    }

    #[test]
    fn bytes_and_errors_are_queued_and_counted_and_a_busy_transmitter_loses_nothing() {
        let mut rx_queue: Queue<u8, 4> = Queue::new();
        let mut tx_queue: Queue<u8, 8> = Queue::new();
        let (mut incoming, mut commands) = rx_queue.split();
        assert_eq!(incoming.capacity(), 3);
        let (mut frames, mut outgoing) = tx_queue.split();
        for b in [1u8, 2, 3] {
            frames.enqueue(b).unwrap();
        }
        let overrun = nb::Error::Other(SerialError::Overrun);
        let mut rx = Receiver([Ok(7), Err(overrun), Ok(8), Ok(9), Ok(10), Ok(11)].into());
        let mut tx = Transmitter {
            sent: Vec::new(),
            busy: false,
        };
        let overruns = AtomicU32::new(0);
        let states: Vec<Transmit> = (0..8)
            .map(|_| serve_uart(&mut rx, &mut tx, &mut outgoing, &mut incoming, &overruns))
            .collect();
        assert_eq!(
            tx.sent,
            [1, 2, 3],
            "every byte once, in order, though the transmitter was busy"
        );
        assert_eq!(states[0], Transmit::Sending);
        assert_eq!(states.last(), Some(&Transmit::Idle));
        // Four reads in the first interrupt (7, an error, 8, 9), then 10 and
        // 11 into the full queue: 7 8 9 queued; the error, 10 and 11 counted.
        let got: Vec<u8> = core::iter::from_fn(|| commands.dequeue()).collect();
        assert_eq!(got, [7, 8, 9]);
        assert_eq!(overruns.load(Ordering::Relaxed), 3);
    }

    #[test]
    fn a_stamp_into_a_full_queue_is_counted_not_lost_silently() {
        let mut queue: Queue<u32, 3> = Queue::new();
        let (mut stamps, mut taken) = queue.split();
        assert_eq!(stamps.capacity(), 2);
        let overruns = AtomicU32::new(0);
        for stamp in [10, 20, 30] {
            stamp_data_ready(stamp, &mut stamps, &overruns);
        }
        assert_eq!(
            (taken.dequeue(), taken.dequeue(), taken.dequeue()),
            (Some(10), Some(20), None)
        );
        assert_eq!(overruns.load(Ordering::Relaxed), 1);
    }
}
