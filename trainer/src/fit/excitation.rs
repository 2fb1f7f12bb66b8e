//! Whether training data can identify a model at all: the least duration,
//! temperature span, ramp and target spread a fit needs.

use rbf_core::FeatureSet;

use crate::dataset::Blocks;

/// Least usable recording, s: a thermal model needs at least ten minutes.
pub const MIN_USABLE_S: f64 = 600.0;
/// Least loop-temperature span, °C, to identify a temperature dependence.
pub const MIN_TEMP_SPAN_C: f64 = 5.0;
/// Least ΔT span, °C/min, for models that use ΔT (the run must contain ramps).
pub const MIN_RATE_SPAN_C_PER_MIN: f64 = 0.2;

/// Training data that cannot identify a model: what is missing (see
/// [`check_excitation`]; `trainer fit` adds the causes it finds in the runs,
/// [`crate::evaluation::diagnose::with_causes`]).
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
pub struct Unidentifiable(pub String);

/// Least spread of the block-mean bias target, °/h: below it the rate
/// column carries no gyro signal (a real gyro's noise alone is larger).
pub const MIN_TARGET_SPREAD_DPH: f64 = 1e-9;

/// Refuses training data that cannot identify a model of `set` with
/// `fixed_centers` Gaussians (one when they are searched), from blocks of
/// `block_s`, saying what is missing.
pub fn check_excitation(
    blocks: &Blocks,
    set: FeatureSet,
    fixed_centers: Option<usize>,
    block_s: f64,
) -> anyhow::Result<()> {
    let mut missing = Vec::new();
    if blocks.usable_s < MIN_USABLE_S {
        missing.push(format!(
            "the training runs hold {:.0} s of usable samples; at least {MIN_USABLE_S:.0} s are needed",
            blocks.usable_s
        ));
    }
    if blocks.is_empty() {
        // Usable samples but no whole block: the block is the cause, not the run.
        let why = if blocks.usable_s > 0.0 {
            format!(
                "no block of {} s is whole: the training runs hold {:.0} s ({:.2} h) of usable samples, less than one block; \
                 --block-s {} is longer than the runs: use a shorter block",
                crate::reading::sampling::sig(block_s),
                blocks.usable_s,
                blocks.usable_s / 3600.0,
                crate::reading::sampling::sig(block_s)
            )
        } else {
            "no usable samples in the training runs (all warming up or sensor faults)".to_owned()
        };
        return Err(Unidentifiable(why).into());
    }
    let (y_lo, y_hi) = blocks
        .y
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &y| {
            (lo.min(y), hi.max(y))
        });
    if y_hi - y_lo < MIN_TARGET_SPREAD_DPH {
        missing.push(format!(
            "the bias target rate_dph − ref_dph is {} °/h in every block: no excitation to fit (is rate_dph the gyro output?)",
            crate::reading::sampling::sig(y_lo)
        ));
    }
    let (lo, hi) = blocks.block_range(0);
    if hi - lo < MIN_TEMP_SPAN_C {
        missing.push(format!(
            "loop temperature spans only {:.2} °C ({lo:.2} … {hi:.2} °C); at least {MIN_TEMP_SPAN_C} °C is needed",
            hi - lo
        ));
    }
    if set != FeatureSet::Temp {
        let first_rate = match set {
            FeatureSet::LagBank(bank) => bank.static_inputs(),
            _ => 1,
        };
        let (lo, hi) = blocks.block_range(first_rate);
        if hi - lo < MIN_RATE_SPAN_C_PER_MIN {
            missing.push(format!(
                "ΔT spans only {:.3} °C/min; at least {MIN_RATE_SPAN_C_PER_MIN} °C/min is needed (the run needs temperature ramps)",
                hi - lo
            ));
        }
    }
    let parameters = 1 + set.dims() + fixed_centers.unwrap_or(1);
    if blocks.len() < 10 * parameters {
        missing.push(format!(
            "{} blocks of {} s is too few for {parameters} parameters",
            blocks.len(),
            blocks.length_s(block_s)
        ));
    }
    if missing.is_empty() {
        Ok(())
    } else {
        Err(Unidentifiable(format!(
            "the training data cannot identify a thermal model: {}. Record a chamber run with temperature holds and ramps.",
            missing.join("; ")
        ))
        .into())
    }
}
