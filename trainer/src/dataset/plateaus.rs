//! Settled plateaus of a run: where the loop held a temperature long enough
//! for the gyro to settle, and the settled bias there (a soak test, IEEE Std
//! 952 style). One rule, used by every command that reports it (`trainer
//! eval`, `trainer report`, the benches through `eval --json`):
//!
//! 1. **Minute blocks.** The run is cut into [`BLOCK_S`] (60-s) blocks on its
//!    own clock, block `k` holding the samples with
//!    `k·60 ≤ time_s − time_s[0] < (k+1)·60`. Each block keeps the mean of the
//!    loop temperature (`temp_c`, or an axis's loop thermometer) and of the
//!    residuals before and after compensation. A block is *complete* when it
//!    holds at least half its nominal samples, at least one temperature, and no
//!    gap (a step longer than [`GAP_PERIODS`] nominal periods) lies inside it
//!    or just before its first sample.
//! 2. **Steady blocks.** Block `k` is steady when it and the
//!    [`STEADY_SPAN_S`] (10) blocks before it are complete, no gap lies
//!    among them, and the loop moved at most [`STEADY_MOVE_C`] (1.5 °C) over
//!    those 10 minutes (0.15 °C/min: far below a chamber ramp, above what a
//!    slow gyro's loop still moves at the end of a long hold). A gap
//!    therefore ends any plateau.
//! 3. **Where the hold ends.** The loop sensor lags the chamber: it shows
//!    the next ramp a minute or more after the chamber began it. Within a
//!    stretch of steady blocks (and the [`STEADY_SPAN_S`] after it), the loop
//!    *departs* at the first block whose mean lies more than [`DEPARTURE_C`]
//!    (0.015 °C) off the straight line through the 10 minutes before it, and
//!    more than [`DEPARTURE_GROWTH`] (2) times as far as the least of the
//!    [`DEPARTURE_GROWTH_S`] (5 min) before (a loop still bending towards
//!    its level lies off its line too, less each minute). The departure
//!    *began* at the first minute of the run of minutes before it that lie
//!    more than [`ONSET_C`] (0.003 °C) off their lines and each farther than
//!    the one before (at most [`STEADY_SPAN_S`] back): the hold is taken to
//!    end [`DEPARTURE_MARGIN_S`] (1 min) before that onset, and the loop may
//!    settle again after it within the same stretch. A stretch that ends by
//!    the loop moving (not by the run's end or a gap) with no departure read
//!    ends its hold [`UNSEEN_DEPARTURE_S`] (15 min) before its last steady
//!    block. A ramp slower than 0.15 °C/min counts as steady.
//! 4. **Plateaus.** A plateau is a stretch whose steady blocks up to the
//!    hold's end last at least [`MIN_STEADY_S`] (30 min); the *settled
//!    window* is its last [`WINDOW_S`] (30 min) before the hold's end. How
//!    well it finds the holds of simulated soak tests: docs/workflow.md,
//!    "The soak test".
//! 5. **Per plateau**: the loop temperature (mean over the window's samples,
//!    °C); how long the loop was steady up to the hold's end (s); the window's start and end on the run's clock (s); the
//!    settled bias, the mean of the residual over the window's samples
//!    (°/h), before and after compensation; the noise of that mean, the
//!    sample standard deviation of the window's one-minute residual means
//!    divided by √(their number) (°/h); the share of the window's samples
//!    whose model inputs lay outside the model's training range (flag 1,
//!    input clamped), %: there the settled bias after compensation is the
//!    model's extrapolation, not what the training runs identified.
//! 6. **Spread**: max − min of the settled biases over the run's plateaus
//!    (°/h), only with at least two plateaus ([`settled_spread_dph`]); and
//!    the same over the plateaus *inside the training range*, those with
//!    less than [`OUTSIDE_RANGE_PCT`] of their window outside it.
//!
//! The residual is `rate − ref` before compensation and `rate_comp − ref`
//! after, `ref` being `ref_dph` or, without it, the run's mean rate (as the
//! rest of `trainer eval` does): the caller hands it in.
//!
//! Everything here is a pure function of slices ([`minute_blocks`],
//! [`settled_plateaus`]) or of a stream folded into the same blocks
//! ([`MinuteBlocker`]), so a streamed evaluation holds one block a minute,
//! whatever the run's sample rate.

use serde::Serialize;

/// A plateau with at least this share of its settled window's samples
/// outside the model's training range, %, counts as outside it: its settled
/// bias after compensation is an extrapolation (most of the window beyond
/// the range's edge).
pub const OUTSIDE_RANGE_PCT: f64 = 50.0;

/// Length of a block the loop temperature is averaged over, s.
pub const BLOCK_S: f64 = 60.0;
/// The span the loop's move is read over for a block to count as steady, s.
pub const STEADY_SPAN_S: f64 = 600.0;
/// Largest move of the loop temperature over [`STEADY_SPAN_S`] for a block to
/// count as steady, °C.
pub const STEADY_MOVE_C: f64 = 1.5;
/// How far a block's mean loop temperature may lie off the straight line
/// through the [`STEADY_SPAN_S`] before it before the loop counts as
/// departing from its hold, °C.
pub const DEPARTURE_C: f64 = 0.015;
/// How far off its line a minute before a departure must lie to count as
/// part of it (its onset), °C: three times the noise of that distance for a
/// TMP117 read at 1 Hz (minute means about 0.001 °C apart).
pub const ONSET_C: f64 = 0.003;
/// A departure is also that many times as far off the line as the least of
/// the [`DEPARTURE_GROWTH_S`] before it.
pub const DEPARTURE_GROWTH: f64 = 2.0;
/// The span whose least distance off the line a departure must exceed
/// [`DEPARTURE_GROWTH`] times, s.
pub const DEPARTURE_GROWTH_S: f64 = 300.0;
/// The hold is taken to end this long before the departure's onset, s.
pub const DEPARTURE_MARGIN_S: f64 = 60.0;
/// A stretch that ends by the loop moving, with no departure read, is taken
/// to have ended its hold at least this long before its last steady block, s.
pub const UNSEEN_DEPARTURE_S: f64 = 900.0;
/// Shortest time the loop must be steady up to a hold's end for a plateau, s.
pub const MIN_STEADY_S: f64 = 1800.0;
/// Length of the settled window at the end of a plateau, s.
pub const WINDOW_S: f64 = 1800.0;
/// A time step longer than this many nominal periods is a gap in the run.
pub const GAP_PERIODS: f64 = 2.0;

/// Steady blocks a plateau needs ([`MIN_STEADY_S`] / [`BLOCK_S`]).
const MIN_STEADY_BLOCKS: usize = (MIN_STEADY_S / BLOCK_S) as usize;
/// Blocks of a full settled window ([`WINDOW_S`] / [`BLOCK_S`]).
const WINDOW_BLOCKS: usize = (WINDOW_S / BLOCK_S) as usize;
/// Blocks of [`STEADY_SPAN_S`].
const SPAN_BLOCKS: usize = (STEADY_SPAN_S / BLOCK_S) as usize;
/// Blocks of [`DEPARTURE_MARGIN_S`].
const MARGIN_BLOCKS: usize = (DEPARTURE_MARGIN_S / BLOCK_S) as usize;
/// Blocks of [`DEPARTURE_GROWTH_S`].
const GROWTH_BLOCKS: usize = (DEPARTURE_GROWTH_S / BLOCK_S) as usize;
/// Blocks of [`UNSEEN_DEPARTURE_S`].
const UNSEEN_BLOCKS: usize = (UNSEEN_DEPARTURE_S / BLOCK_S) as usize;

/// The rule in one sentence, for the tables and reports that state it.
pub fn rule_text() -> String {
    format!(
        "plateau: the loop's 60-s means moved at most {STEADY_MOVE_C} °C over {:.0} min, for at least {:.0} min up to \
         {:.0} min before it begins leaving its level (a gap ends it); settled bias: the mean residual over those \
         last {:.0} min; noise: STD of its minute means / √n",
        STEADY_SPAN_S / 60.0,
        MIN_STEADY_S / 60.0,
        DEPARTURE_MARGIN_S / 60.0,
        WINDOW_S / 60.0
    )
}

/// What a plateau's share outside the training range means, in one
/// sentence, for the tables and reports that show it.
pub fn outside_rule_text() -> String {
    format!(
        "outside: share of the settled window where the model's inputs lay outside its training range (flag 1): the \
         settled bias after compensation there is the model's extrapolation; a plateau outside for {OUTSIDE_RANGE_PCT:.0} % \
         of its window or more is left out of the spread inside the range"
    )
}

/// The sums of one 60-s block of a run.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct MinuteBlock {
    /// Block number on the run's clock: the block spans
    /// `first_time_s + index·60 … + 60` s.
    pub index: u64,
    /// Samples in the block.
    pub samples: usize,
    /// Samples with a loop temperature.
    pub temp_samples: usize,
    /// Sum of the loop temperature, °C.
    pub temp_sum_c: f64,
    /// Sum of the residual before compensation, °/h.
    pub before_sum_dph: f64,
    /// Sum of the residual after compensation, °/h.
    pub after_sum_dph: f64,
    /// Samples whose model inputs lay outside the training range (flag 1,
    /// input clamped).
    pub outside_range: usize,
    /// A gap lies inside the block or just before its first sample.
    pub gap: bool,
}

impl MinuteBlock {
    fn mean_temp_c(&self) -> f64 {
        self.temp_sum_c / self.temp_samples as f64
    }

    fn mean_before_dph(&self) -> f64 {
        self.before_sum_dph / self.samples as f64
    }

    fn mean_after_dph(&self) -> f64 {
        self.after_sum_dph / self.samples as f64
    }
}

/// Folds a run's samples, in time order, into [`MinuteBlock`]s.
#[derive(Clone, Debug)]
pub struct MinuteBlocker {
    nominal_period_s: f64,
    first_time_s: Option<f64>,
    last_time_s: f64,
    pending_gap: bool,
    blocks: Vec<MinuteBlock>,
}

impl MinuteBlocker {
    /// A blocker for a run sampled every `nominal_period_s`, s.
    pub fn new(nominal_period_s: f64) -> Self {
        MinuteBlocker {
            nominal_period_s,
            first_time_s: None,
            last_time_s: f64::NAN,
            pending_gap: false,
            blocks: Vec::new(),
        }
    }

    /// Takes one sample at `time_s` (s): its loop temperature (°C; `None` or
    /// not finite: none read), its residuals before and after compensation
    /// (°/h) and whether the model's inputs lay outside its training range
    /// there (`outside_range`: flag 1, input clamped).
    pub fn push(&mut self, time_s: f64, temp_c: Option<f64>, before_dph: f64, after_dph: f64, outside_range: bool) {
        let first = *self.first_time_s.get_or_insert(time_s);
        if time_s - self.last_time_s > GAP_PERIODS * self.nominal_period_s {
            self.pending_gap = true;
        }
        self.last_time_s = time_s;
        let index = ((time_s - first) / BLOCK_S).floor().max(0.0) as u64;
        if self.blocks.last().is_none_or(|b| b.index != index) {
            self.blocks.push(MinuteBlock {
                index,
                ..MinuteBlock::default()
            });
        }
        let Some(block) = self.blocks.last_mut() else {
            return;
        };
        block.gap |= std::mem::take(&mut self.pending_gap);
        block.samples += 1;
        if let Some(t) = temp_c.filter(|t| t.is_finite()) {
            block.temp_samples += 1;
            block.temp_sum_c += t;
        }
        block.before_sum_dph += before_dph;
        block.after_sum_dph += after_dph;
        block.outside_range += usize::from(outside_range);
    }

    /// The run's first sample time, s (`None` before any sample).
    pub fn first_time_s(&self) -> Option<f64> {
        self.first_time_s
    }

    /// The blocks, in time order.
    pub fn finish(self) -> Vec<MinuteBlock> {
        self.blocks
    }
}

/// The [`MinuteBlock`]s of a run given as slices of equal length, in time
/// order: `time_s` (s), `temp_c` (°C, NaN where none was read) and the
/// residuals before and after compensation (°/h), every sample inside the
/// model's training range; `nominal_period_s` (s).
pub fn minute_blocks(
    time_s: &[f64],
    temp_c: &[f64],
    before_dph: &[f64],
    after_dph: &[f64],
    nominal_period_s: f64,
) -> Vec<MinuteBlock> {
    let mut blocker = MinuteBlocker::new(nominal_period_s);
    for (((&t, &temp), &before), &after) in time_s.iter().zip(temp_c).zip(before_dph).zip(after_dph) {
        blocker.push(t, Some(temp), before, after, false);
    }
    blocker.finish()
}

/// One settled plateau of a run (the rule: the module's documentation).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct SettledPlateau {
    /// Loop temperature, mean over the settled window, °C.
    pub temp_c: f64,
    /// Length of the steady stretch (its last block included), s.
    pub steady_s: f64,
    /// Start of the settled window on the run's clock (`time_s`), s.
    pub window_start_s: f64,
    /// End of the settled window on the run's clock, s.
    pub window_end_s: f64,
    /// Settled bias before compensation: mean of `rate − ref` over the window, °/h.
    pub bias_before_dph: f64,
    /// Settled bias after compensation: mean of `rate_comp − ref` over the window, °/h.
    pub bias_after_dph: f64,
    /// Noise of `bias_after_dph`: standard deviation of the window's one-minute
    /// compensated residual means / √(their number), °/h.
    pub noise_dph: f64,
    /// Noise of `bias_before_dph`, the same way, °/h.
    pub noise_before_dph: f64,
    /// Share of the window's samples whose model inputs lay outside the
    /// model's training range (flag 1, input clamped), %: there
    /// `bias_after_dph` is the model's extrapolation.
    pub outside_range_pct: f64,
}

impl SettledPlateau {
    /// Whether the plateau lies outside the model's training range: at least
    /// [`OUTSIDE_RANGE_PCT`] of its window there.
    pub fn outside_range(&self) -> bool {
        self.outside_range_pct >= OUTSIDE_RANGE_PCT
    }
}

/// The settled plateaus of a run from its [`MinuteBlock`]s (in time order;
/// `first_time_s`: the run's first sample time, s; `nominal_period_s`: its
/// nominal sample period, s), in time order.
pub fn settled_plateaus(blocks: &[MinuteBlock], first_time_s: f64, nominal_period_s: f64) -> Vec<SettledPlateau> {
    let (Some(first), Some(last)) = (blocks.first(), blocks.last()) else {
        return Vec::new();
    };
    let nominal_samples = BLOCK_S / nominal_period_s;
    let complete = |b: &MinuteBlock| !b.gap && b.temp_samples > 0 && b.samples as f64 >= 0.5 * nominal_samples;
    // Minute by minute from the first block: the block there, if complete.
    let minutes = (last.index - first.index) as usize + 1;
    let mut at: Vec<Option<&MinuteBlock>> = vec![None; minutes];
    for b in blocks.iter().filter(|b| complete(b)) {
        at[(b.index - first.index) as usize] = Some(b);
    }
    let temp = |k: usize| at[k].map(MinuteBlock::mean_temp_c);
    // The minutes `from ..= to` are all complete (a gap makes its block incomplete).
    let whole = |from: usize, to: usize| (from..=to).all(|m| at[m].is_some());
    let steady: Vec<bool> = (0..minutes)
        .map(|k| {
            k >= SPAN_BLOCKS
                && whole(k - SPAN_BLOCKS, k)
                && temp(k)
                    .zip(temp(k - SPAN_BLOCKS))
                    .is_some_and(|(now, before)| (now - before).abs() <= STEADY_MOVE_C)
        })
        .collect();
    // The loop at minute k off the line through the 10 minutes before it, °C.
    let off_line: Vec<Option<f64>> = (0..minutes)
        .map(|k| {
            let from = k.checked_sub(1 + SPAN_BLOCKS)?;
            if !whole(from, k) {
                return None;
            }
            let (t_k, t_prev, t_from) = (temp(k)?, temp(k - 1)?, temp(from)?);
            Some((t_k - (t_prev + (t_prev - t_from) / SPAN_BLOCKS as f64)).abs())
        })
        .collect();
    // The loop departs at k: off its line by more than DEPARTURE_C, and by
    // DEPARTURE_GROWTH times the least it was in the minutes before (a loop
    // still bending towards its level is off its line too, less each minute).
    let departs = |k: usize| -> Option<bool> {
        let now = off_line[k]?;
        let least = off_line[k - GROWTH_BLOCKS..k]
            .iter()
            .try_fold(f64::INFINITY, |least, off| off.map(|o| least.min(o)))?;
        Some(now > DEPARTURE_C && now > DEPARTURE_GROWTH * least)
    };
    let mut plateaus = Vec::new();
    let mut i = 0;
    while i < minutes {
        if !steady[i] {
            i += 1;
            continue;
        }
        let mut j = i;
        while j + 1 < minutes && steady[j + 1] {
            j += 1;
        }
        let mut departure = None;
        for k in (i + SPAN_BLOCKS + 1 + GROWTH_BLOCKS)..=(j + SPAN_BLOCKS).min(minutes - 1) {
            match departs(k) {
                None => break,
                Some(true) => {
                    departure = Some(k);
                    break;
                }
                Some(false) => {}
            }
        }
        // Ended by the loop moving (the next minute is there but not steady)?
        let moved_on = j + 1 < minutes && whole(j + 1 - SPAN_BLOCKS, j + 1);
        let end = match departure {
            Some(k) => onset_of(k, i, &off_line).checked_sub(1 + MARGIN_BLOCKS),
            None if moved_on => j.checked_sub(UNSEEN_BLOCKS),
            None => Some(j),
        };
        if let Some(end) = end.filter(|&e| e >= i && e + 1 - i >= MIN_STEADY_BLOCKS) {
            let window: Vec<MinuteBlock> = (end + 1 - WINDOW_BLOCKS..=end).filter_map(|m| at[m].copied()).collect();
            plateaus.push(plateau_of(&window, end + 1 - i, first_time_s));
        }
        // After a departure the loop may settle again within the same stretch.
        i = departure.map_or(j, |k| k) + 1;
    }
    plateaus
}

/// The minute the departure at `k` began: back from `k` (not before the
/// stretch's start `from`, nor more than [`STEADY_SPAN_S`]) while the minute
/// before lies more than [`ONSET_C`] off its line and less far than the one after.
fn onset_of(k: usize, from: usize, off_line: &[Option<f64>]) -> usize {
    let mut onset = k;
    while onset > from + 1 && onset + SPAN_BLOCKS > k {
        match (off_line[onset - 1], off_line[onset]) {
            (Some(before), Some(now)) if before > ONSET_C && before < now => onset -= 1,
            _ => break,
        }
    }
    onset
}

/// The figures of a settled `window` (complete blocks) of a steady stretch of `steady_blocks`.
fn plateau_of(window: &[MinuteBlock], steady_blocks: usize, first_time_s: f64) -> SettledPlateau {
    let samples: usize = window.iter().map(|b| b.samples).sum();
    let temp_samples: usize = window.iter().map(|b| b.temp_samples).sum();
    let sum = |f: fn(&MinuteBlock) -> f64| window.iter().map(f).sum::<f64>();
    let start_index = window.first().map_or(0, |b| b.index);
    let end_index = window.last().map_or(0, |b| b.index + 1);
    SettledPlateau {
        temp_c: sum(|b| b.temp_sum_c) / temp_samples as f64,
        steady_s: steady_blocks as f64 * BLOCK_S,
        window_start_s: first_time_s + start_index as f64 * BLOCK_S,
        window_end_s: first_time_s + end_index as f64 * BLOCK_S,
        bias_before_dph: sum(|b| b.before_sum_dph) / samples as f64,
        bias_after_dph: sum(|b| b.after_sum_dph) / samples as f64,
        noise_dph: noise_of_mean(window.iter().map(MinuteBlock::mean_after_dph)),
        noise_before_dph: noise_of_mean(window.iter().map(MinuteBlock::mean_before_dph)),
        outside_range_pct: 100.0 * window.iter().map(|b| b.outside_range).sum::<usize>() as f64 / samples as f64,
    }
}

/// Sample standard deviation of `means` / √(their number); NaN for fewer than two.
fn noise_of_mean(means: impl Iterator<Item = f64> + Clone) -> f64 {
    let n = means.clone().count();
    if n < 2 {
        return f64::NAN;
    }
    let mean = means.clone().sum::<f64>() / n as f64;
    let variance = means.map(|m| (m - mean).powi(2)).sum::<f64>() / (n - 1) as f64;
    (variance / n as f64).sqrt()
}

/// The spread of settled biases, max − min, °/h; `None` with fewer than two.
pub fn settled_spread_dph(biases_dph: impl IntoIterator<Item = f64>) -> Option<f64> {
    let (n, lo, hi) = biases_dph
        .into_iter()
        .fold((0usize, f64::INFINITY, f64::NEG_INFINITY), |(n, lo, hi), b| {
            (n + 1, lo.min(b), hi.max(b))
        });
    (n >= 2).then_some(hi - lo)
}

/// A run's settled plateaus and the spread of their bias before and after
/// compensation: what `trainer eval --json` carries per run (and axis).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SettledBias {
    /// Spread (max − min) of the settled bias after compensation, °/h; `None`
    /// (null) without at least two plateaus.
    pub settled_spread_dph: Option<f64>,
    /// The same before compensation, °/h.
    pub settled_spread_before_dph: Option<f64>,
    /// Spread after compensation over the plateaus inside the model's
    /// training range ([`SettledPlateau::outside_range`] false), °/h; `None`
    /// without two such plateaus. Below `settled_spread_dph` where the model
    /// extrapolates worse than it fits.
    pub settled_spread_in_range_dph: Option<f64>,
    /// The plateaus, in time order.
    pub plateaus: Vec<SettledPlateau>,
}

impl SettledBias {
    /// The plateaus of `blocks` (see [`settled_plateaus`]), their biases taken
    /// about `offset_dph` (the run's mean rate when the residuals were summed
    /// without `ref_dph`, else 0), and their spreads.
    pub fn of(blocks: &[MinuteBlock], first_time_s: f64, nominal_period_s: f64, offset_dph: f64) -> Self {
        let plateaus: Vec<SettledPlateau> = settled_plateaus(blocks, first_time_s, nominal_period_s)
            .into_iter()
            .map(|p| SettledPlateau {
                bias_before_dph: p.bias_before_dph - offset_dph,
                bias_after_dph: p.bias_after_dph - offset_dph,
                ..p
            })
            .collect();
        SettledBias {
            settled_spread_dph: settled_spread_dph(plateaus.iter().map(|p| p.bias_after_dph)),
            settled_spread_before_dph: settled_spread_dph(plateaus.iter().map(|p| p.bias_before_dph)),
            settled_spread_in_range_dph: settled_spread_dph(
                plateaus.iter().filter(|p| !p.outside_range()).map(|p| p.bias_after_dph),
            ),
            plateaus,
        }
    }
}

/// The loop temperatures of the settled plateaus
/// in means of the loop temperature `temp_c` starting at `time_s` on their
/// run's clock, of run `run`, each `period_s` long, °C.
pub fn settled_levels_c(time_s: &[f64], temp_c: &[f64], run: &[usize], period_s: f64) -> Vec<f64> {
    settled_windows(time_s, temp_c, run, period_s)
        .iter()
        .map(|w| w.temp_c)
        .collect()
}

/// A settled plateau's window in means of the loop temperature
/// ([`settled_windows`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SettledWindow {
    /// The run it lies in.
    pub run: usize,
    /// Loop temperature, mean over the window, °C.
    pub temp_c: f64,
    /// Start of the window on the run's clock, s.
    pub start_s: f64,
    /// End of the window on the run's clock, s.
    pub end_s: f64,
}

/// The settled plateaus' windows in means of the loop temperature `temp_c`
/// starting at `time_s` on their run's clock, of run `run` (consecutive
/// means of one run together), each `period_s` long; in time order per run.
pub fn settled_windows(time_s: &[f64], temp_c: &[f64], run: &[usize], period_s: f64) -> Vec<SettledWindow> {
    let mut out = Vec::new();
    let mut start = 0;
    while start < run.len() {
        let end = (start..run.len()).find(|&i| run[i] != run[start]).unwrap_or(run.len());
        let mut blocker = MinuteBlocker::new(period_s);
        for (&t, &temp) in time_s[start..end].iter().zip(&temp_c[start..end]) {
            blocker.push(t, Some(temp), 0.0, 0.0, false);
        }
        let first_s = blocker.first_time_s().unwrap_or(0.0);
        out.extend(
            settled_plateaus(&blocker.finish(), first_s, period_s)
                .iter()
                .map(|p| SettledWindow {
                    run: run[start],
                    temp_c: p.temp_c,
                    start_s: p.window_start_s,
                    end_s: p.window_end_s,
                }),
        );
        start = end;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 1-Hz run of the loop temperature `temp(t)` with residuals
    /// `before(t)`, `after(t)`; the times `time_s` (s).
    fn run(
        time_s: &[f64],
        temp: impl Fn(f64) -> f64,
        before: impl Fn(f64) -> f64,
        after: impl Fn(f64) -> f64,
    ) -> Vec<SettledPlateau> {
        let t = |f: &dyn Fn(f64) -> f64| time_s.iter().map(|&t| f(t)).collect::<Vec<_>>();
        let blocks = minute_blocks(time_s, &t(&temp), &t(&before), &t(&after), 1.0);
        settled_plateaus(&blocks, time_s[0], 1.0)
    }

    fn seconds(from_s: f64, to_s: f64) -> Vec<f64> {
        (0..((to_s - from_s) as usize)).map(|i| from_s + i as f64).collect()
    }

    /// Holds of `hold_s` at `levels`, 1 °C/min ramps between; the time each hold ends.
    fn staircase(levels: &[f64], hold_s: f64) -> (impl Fn(f64) -> f64 + Clone, Vec<f64>, f64) {
        let mut knots = vec![(0.0, levels[0]), (hold_s, levels[0])];
        for &l in &levels[1..] {
            let (t, c) = *knots.last().unwrap();
            knots.push((t + (l - c).abs() * 60.0, l));
            knots.push((t + (l - c).abs() * 60.0 + hold_s, l));
        }
        let ends: Vec<f64> = knots.iter().skip(1).step_by(2).map(|k| k.0).collect();
        let end = knots.last().unwrap().0;
        let temp = move |t: f64| {
            let i = knots.partition_point(|k| k.0 <= t).clamp(1, knots.len() - 1);
            let (a, b) = (knots[i - 1], knots[i]);
            if b.0 > a.0 {
                a.1 + (b.1 - a.1) * ((t - a.0) / (b.0 - a.0)).clamp(0.0, 1.0)
            } else {
                b.1
            }
        };
        (temp, ends, end)
    }

    #[test]
    fn a_staircase_of_holds_gives_each_hold_read_over_its_last_30_min() {
        let levels = [25.0, 0.0, 40.0, -20.0];
        let (temp, hold_ends, end) = staircase(&levels, 3.0 * 3600.0);
        // The bias follows the level: 0.01 °/h per °C before, a tenth after.
        let time = seconds(0.0, end);
        let plateaus = run(&time, &temp, |t| 0.01 * temp(t), |t| 0.001 * temp(t));
        assert_eq!(plateaus.len(), levels.len(), "{plateaus:#?}");
        for ((p, level), hold_end) in plateaus.iter().zip(levels).zip(hold_ends) {
            assert!((p.temp_c - level).abs() < 1e-9, "{p:?} at {level} °C");
            assert!(
                (p.window_end_s - p.window_start_s - WINDOW_S).abs() < 1e-9,
                "30-min window: {p:?}"
            );
            // The window ends where the hold does, less the margin for the
            // departure the loop shows (the next ramp's first minute), or
            // where the run does.
            assert!(
                p.window_end_s <= hold_end && p.window_end_s >= hold_end - DEPARTURE_MARGIN_S - 2.0 * BLOCK_S,
                "window ends before the hold's end {hold_end} s: {p:?}"
            );
            assert!(
                p.steady_s >= 3.0 * 3600.0 - STEADY_SPAN_S - DEPARTURE_MARGIN_S - 2.0 * BLOCK_S,
                "{p:?}"
            );
            assert!((p.bias_before_dph - 0.01 * level).abs() < 1e-9);
            assert!((p.bias_after_dph - 0.001 * level).abs() < 1e-9);
        }
        let spread = settled_spread_dph(plateaus.iter().map(|p| p.bias_after_dph)).unwrap();
        assert!((spread - 0.001 * 60.0).abs() < 1e-9, "{spread}");
    }

    #[test]
    fn a_slow_loop_parts_holds_5_c_apart_and_ends_each_within_3_min_of_the_chamber_s() {
        // The chamber's staircase seen through lags of 20 and 30 min (a slow
        // gyro's loop): its 5-°C steps move it at most 0.025 °C off its line
        // and never faster than 0.15 °C/min, so it stays "steady" across them;
        // the departure's onset still parts those holds, and each window ends
        // within 3 min of the chamber's hold end (a minute or two into the
        // next ramp, which the loop and the coil behind it have not felt yet).
        let levels = [20.0, 25.0, 15.0, 35.0, 30.0];
        let (chamber, hold_ends, end) = staircase(&levels, 3.0 * 3600.0);
        let time = seconds(0.0, end);
        let (mut outer, mut loop_c) = (levels[0], levels[0]);
        let lagged: Vec<f64> = time
            .iter()
            .map(|&t| {
                outer += (chamber(t) - outer) / 1200.0;
                loop_c += (outer - loop_c) / 1800.0;
                loop_c
            })
            .collect();
        let zeros = vec![0.0; time.len()];
        let blocks = minute_blocks(&time, &lagged, &zeros, &zeros, 1.0);
        let plateaus = settled_plateaus(&blocks, 0.0, 1.0);
        assert_eq!(plateaus.len(), levels.len(), "{plateaus:#?}");
        for (p, hold_end) in plateaus.iter().zip(&hold_ends[..levels.len() - 1]) {
            assert!(
                (p.window_end_s - hold_end).abs() <= 3.0 * BLOCK_S,
                "window ends within 3 min of the hold's end {hold_end} s: {p:?}"
            );
        }
    }

    #[test]
    fn ramps_give_no_plateau_nor_spread() {
        // 1 °C/min up and down, and 0.2 °C/min: the loop moves more than
        // 1.5 °C in every 10 min.
        let time = seconds(0.0, 6.0 * 3600.0);
        let zigzag = |t: f64| 50.0 - ((t / 60.0) % 100.0 - 50.0).abs();
        assert!(run(&time, zigzag, |_| 0.0, |_| 0.0).is_empty());
        let slow = |t: f64| 0.2 * t / 60.0;
        let plateaus = run(&time, slow, |_| 0.0, |_| 0.0);
        assert!(plateaus.is_empty());
        assert_eq!(settled_spread_dph(plateaus.iter().map(|p| p.bias_after_dph)), None);
    }

    #[test]
    fn a_35_min_hold_is_no_plateau_a_45_min_one_is() {
        // After a ramp the loop is steady once its last 10 min moved ≤ 1.5 °C
        // (8.5 min into an ideal hold); the window ends a minute before the
        // next ramp begins to show: 30 steady minutes need a hold of about 40 min.
        for (hold_min, expected) in [(20.0, 0), (35.0, 0), (45.0, 1)] {
            let (temp, _, end) = staircase(&[0.0, 30.0, 60.0], hold_min * 60.0);
            let plateaus = run(&seconds(0.0, end), temp, |_| 0.0, |_| 0.0);
            // The last hold runs to the run's end; only the middle one counts.
            let middle = plateaus.iter().filter(|p| (p.temp_c - 30.0).abs() < 1e-6).count();
            assert_eq!(middle, expected, "{hold_min}-min hold: {plateaus:?}");
        }
        let one = settled_spread_dph([0.3]);
        assert_eq!(one, None, "one plateau has no spread");
    }

    #[test]
    fn a_gap_ends_a_plateau() {
        // A 3-h hold at 20 °C with a 10-min gap at 1 h 40 min: the stretch
        // before it (100 min) and after it (80 min) are plateaus of their own.
        let mut time = seconds(0.0, 6000.0);
        time.extend(seconds(6600.0, 3.0 * 3600.0));
        let plateaus = run(&time, |_| 20.0, |_| 1.0, |_| 0.0);
        assert_eq!(plateaus.len(), 2, "{plateaus:#?}");
        assert!(plateaus[0].window_end_s <= 6000.0);
        assert!(plateaus[1].window_start_s >= 6600.0);
        // Steady from minute 10 (the first with 10 minutes before it) to 99,
        // the last before the gap; no departure read across the gap.
        assert!((plateaus[0].steady_s - 90.0 * 60.0).abs() < 1e-9, "{:?}", plateaus[0]);
        // After the gap: its block is incomplete, the next is steady 10
        // minutes later (minute 121), to the run's end (minute 179).
        assert!((plateaus[1].steady_s - 59.0 * 60.0).abs() < 1e-9, "{:?}", plateaus[1]);
    }

    #[test]
    fn the_noise_is_the_spread_of_the_minute_means_over_root_30() {
        // A hold whose compensated residual alternates ±a by minute: 30
        // window minutes (15 each way) have sample STD a·√(30/29), so the
        // noise of their mean is a·√(30/29)/√30 = a/√29.
        let a = 0.006;
        let time = seconds(0.0, 2.0 * 3600.0);
        let after = move |t: f64| {
            if ((t / 60.0).floor() as u64).is_multiple_of(2) {
                a
            } else {
                -a
            }
        };
        let plateaus = run(&time, |_| 10.0, |_| 0.0, after);
        assert_eq!(plateaus.len(), 1);
        let p = plateaus[0];
        assert!((p.noise_dph - a / 29f64.sqrt()).abs() < 1e-12, "{p:?}");
        assert!(p.bias_after_dph.abs() < 1e-12, "{p:?}");
        assert_eq!(p.noise_before_dph.to_bits(), 0f64.to_bits(), "a constant has no noise");
    }

    #[test]
    fn a_plateau_the_model_extrapolates_at_is_marked_and_left_out_of_the_spread_inside_the_range() {
        // Holds at 0, 20 and 40 °C; the model's training range ends at 30 °C,
        // and past it the compensated residual is 0.5 °/h off (extrapolation).
        let (temp, _, end) = staircase(&[0.0, 20.0, 40.0], 3600.0);
        let after = |t: f64| match temp(t) {
            c if c > 30.0 => 0.5,
            c if c > 10.0 => 0.01,
            _ => 0.0,
        };
        let mut blocker = MinuteBlocker::new(1.0);
        for t in seconds(0.0, end) {
            blocker.push(t, Some(temp(t)), 0.0, after(t), temp(t) > 30.0);
        }
        let settled = SettledBias::of(&blocker.finish(), 0.0, 1.0, 0.0);
        let outside: Vec<f64> = settled.plateaus.iter().map(|p| p.outside_range_pct).collect();
        assert_eq!(outside, [0.0, 0.0, 100.0], "{settled:?}");
        assert!(settled.plateaus[2].outside_range() && !settled.plateaus[1].outside_range());
        let close = |a: Option<f64>, b: f64| a.is_some_and(|a| (a - b).abs() < 1e-9);
        assert!(close(settled.settled_spread_dph, 0.5), "{settled:?}");
        assert!(close(settled.settled_spread_in_range_dph, 0.01), "{settled:?}");
    }

    #[test]
    fn a_window_half_outside_the_range_counts_as_outside() {
        // One 2-h hold; the last 15 of its settled window's 30 minutes outside.
        let end = 2.0 * 3600.0;
        let mut blocker = MinuteBlocker::new(1.0);
        for t in seconds(0.0, end) {
            blocker.push(t, Some(20.0), 0.0, 0.0, t >= end - 900.0);
        }
        let settled = SettledBias::of(&blocker.finish(), 0.0, 1.0, 0.0);
        let p = &settled.plateaus[0];
        assert!((p.outside_range_pct - 50.0).abs() < 1e-9, "{p:?}");
        assert!(p.outside_range());
        assert_eq!(settled.settled_spread_in_range_dph, None);
    }
}
