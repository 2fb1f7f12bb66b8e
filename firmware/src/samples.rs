//! The sample half of a pass of the board's loop (`Board::run`), as host
//! code the fault campaign runs too: the pacer turns the data-ready stamps
//! (or the silence) into one compensation step, the watchdog is fed by the
//! step, and a `bench` command in progress times the step on a cycle
//! counter and sends its report after the last timed step.

use embedded_io::Write;

use crate::bench::{Bench, CycleStats};
use crate::compensation::{CompensationLoop, ModelHolder, write_frame};
use crate::pacing::{self, Pacer};
use crate::sensors::{AxisFrontEnds, AxisThermometers};
use crate::watchdog::Watchdog;

/// One step for the newest stamp `next_stamp` gives at `now_ticks` (or
/// for the silence, when the pacer synthesises one), timed on `cycles`
/// (a free-running counter) for `bench`; `stepped` hears the step's
/// sequence number and, after the bench's last step, its statistics (the
/// report frame is already queued then). Whether a step ran.
#[allow(clippy::too_many_arguments, reason = "the loop's parts, each borrowed for one pass")]
pub fn serve_samples_timed<T, R, W, M, D, const K: usize, const N: usize>(
    pacer: &mut Pacer,
    next_stamp: impl FnMut() -> Option<u32>,
    now_ticks: u32,
    watchdog: &mut D,
    compensation: &mut CompensationLoop<T, R, W, M, K, N>,
    bench: &mut Bench,
    mut cycles: impl FnMut() -> u32,
    mut stepped: impl FnMut(u32, Option<CycleStats>),
) -> bool
where
    T: AxisThermometers,
    R: AxisFrontEnds,
    W: Write,
    M: ModelHolder<K, N>,
    D: Watchdog,
{
    pacing::serve_samples(pacer, next_stamp, now_ticks, watchdog, |tick| {
        let started = cycles();
        compensation.step_at(tick.seq, tick.dt_s);
        let stats = bench.record(cycles().wrapping_sub(started));
        if let Some(stats) = stats {
            let mut report = [0u8; 24];
            if let Some(n) = stats.encode_report(&mut report) {
                write_frame(compensation.output_mut(), report.get(..n).unwrap_or(&[]));
            }
        }
        stepped(tick.seq, stats);
    })
}
