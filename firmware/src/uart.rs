//! The output side of an interrupt-driven UART: frames go into a
//! single-producer single-consumer byte queue (heapless `spsc`) that the
//! transmit interrupt drains, one byte per TXE event; the sample loop never
//! waits on the wire.
//!
//! [`FrameQueue`] takes a frame whole or not at all: with room for it, every
//! byte is queued and the transmitter is started; without, the frame is
//! dropped and counted (the loop flags the next frame that goes out,
//! [`rbf_core::Flags::OUTPUT_DROPPED`]). Half a frame never reaches the
//! wire, so a receiver's COBS framing stays in step.
//!
//! The receive side is the mirror image on the board: the receive
//! interrupt pushes each byte into another `spsc` queue and counts overruns
//! (a byte the hardware or the full queue lost); the main loop pops them
//! into [`crate::update::CommandReceiver`].

use heapless::spsc::{Consumer, Producer};

/// `producer.enqueue(value)` with no panic path. heapless 0.9 computes queue
/// positions modulo `capacity + 1`, a run-time value behind the producer's
/// view, so every `enqueue` and `dequeue` links a division-by-zero panic;
/// testing that value first (it is never 0: a queue holds at least one
/// slot) lets the optimiser drop it. The board's interrupt handlers and its
/// loop use these, and `cargo xtask check-board-panics` proves from the
/// image that no panic is left (docs/panic-free.md).
#[inline(always)]
pub fn enqueue<T>(producer: &mut Producer<'_, T>, value: T) -> Result<(), T> {
    if producer.capacity() == usize::MAX {
        return Err(value);
    }
    producer.enqueue(value)
}

/// `consumer.dequeue()` with no panic path (see [`enqueue`]).
#[inline(always)]
pub fn dequeue<T>(consumer: &mut Consumer<'_, T>) -> Option<T> {
    if consumer.capacity() == usize::MAX {
        return None;
    }
    consumer.dequeue()
}

/// Why a frame was not queued.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct QueueFull;

impl embedded_io::Error for QueueFull {
    fn kind(&self) -> embedded_io::ErrorKind {
        embedded_io::ErrorKind::OutOfMemory
    }
}

/// The producer end of the transmit queue, as an [`embedded_io::Write`]
/// that takes a buffer whole or refuses it.
pub struct FrameQueue<'a, S> {
    bytes: Producer<'a, u8>,
    start: S,
    dropped: u32,
}

impl<'a, S: FnMut()> FrameQueue<'a, S> {
    /// Frames go into `bytes`; `start` is called after each queued frame
    /// (the board enables the TXE interrupt there).
    pub fn new(bytes: Producer<'a, u8>, start: S) -> Self {
        FrameQueue {
            bytes,
            start,
            dropped: 0,
        }
    }

    /// Frames refused for want of room since start.
    pub fn dropped(&self) -> u32 {
        self.dropped
    }

    /// Bytes that fit now.
    pub fn free(&self) -> usize {
        // The test for a zero modulus (capacity + 1 = 0) drops `len`'s
        // division-by-zero panic, as in [`enqueue`].
        let capacity = self.bytes.capacity();
        if capacity == usize::MAX {
            return 0;
        }
        capacity.saturating_sub(self.bytes.len())
    }

    /// Queues `frame` whole and starts the transmitter, or drops it.
    pub fn push(&mut self, frame: &[u8]) -> Result<(), QueueFull> {
        if frame.len() > self.free() {
            self.dropped = self.dropped.wrapping_add(1);
            return Err(QueueFull);
        }
        for &b in frame {
            // Cannot fail: the room was checked, and only this end adds bytes.
            let _ = enqueue(&mut self.bytes, b);
        }
        (self.start)();
        Ok(())
    }
}

impl<S> embedded_io::ErrorType for FrameQueue<'_, S> {
    type Error = QueueFull;
}

impl<S: FnMut()> embedded_io::Write for FrameQueue<'_, S> {
    /// All of `buf` or an error; never `Ok(0)` for a non-empty buffer.
    fn write(&mut self, buf: &[u8]) -> Result<usize, QueueFull> {
        self.push(buf).map(|()| buf.len())
    }

    fn flush(&mut self) -> Result<(), QueueFull> {
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::compensation::write_frame;
    use heapless::spsc::Queue;

    #[test]
    fn a_frame_goes_in_whole_or_is_dropped_and_counted() {
        let mut queue: Queue<u8, 8> = Queue::new();
        let (tx, mut rx) = queue.split();
        let starts = core::cell::Cell::new(0);
        let mut frames = FrameQueue::new(tx, || starts.set(starts.get() + 1));
        assert_eq!(frames.free(), 7);
        assert!(write_frame(&mut frames, &[1, 2, 3, 0]));
        assert!(!write_frame(&mut frames, &[4, 5, 6, 7, 0]), "5 bytes do not fit in 3");
        assert_eq!(frames.dropped(), 1);
        assert!(write_frame(&mut frames, &[8, 9, 0]));
        assert_eq!(starts.get(), 2, "the transmitter starts once per queued frame");
        let sent: std::vec::Vec<u8> = core::iter::from_fn(|| rx.dequeue()).collect();
        assert_eq!(sent, [1, 2, 3, 0, 8, 9, 0], "no byte of the dropped frame");
    }
}
