//! The first-order derivative filter every ΔT is read through: the lag
//! bank's and the multi-scale sets' ΔT filters ([`crate::features`]) and the
//! response bank's twelve filters of three signals ([`crate::response_bank`]).
//!
//! ```text
//! rate_i = (x_i − S_{i−1}) / (τ + dt_i)      [unit/s, returned ×60 per minute]
//! S_i    = S_{i−1} + dt_i · rate_i           (S: the smoothed signal; τ = 0: S_i = x_i)
//! ```
//!
//! As idsp's filters, the state ([`DerivativeFilter`], one `f32`) is apart
//! from the coefficients (τ and dt, or [`DerivativeGain`] computed from them).
//! The filter has two update forms with the same arithmetic up to the last
//! bit: [`DerivativeFilter::update`] divides by τ + dt, as the feature sets
//! always have; [`DerivativeFilter::update_with`] multiplies by the
//! reciprocal in a [`DerivativeGain`], one division shared by the response
//! bank's three signals per filter (the firmware's instruction budget).
//! Every stored model was fitted with the form its feature set uses, so
//! each keeps its own: the blobs and the QEMU replays stay bit for bit.

/// Seconds per minute: rates are returned per minute.
pub const SECONDS_PER_MINUTE: f32 = 60.0;

/// A derivative filter's gains for one step of `dt_s` at time constant
/// `tau_s`: the state's share of the difference, dt/(τ + dt), and the rate
/// per minute per unit of difference, 60/(τ + dt).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DerivativeGain {
    step: f32,
    per_min: f32,
}

impl DerivativeGain {
    /// The gains of a filter of time constant `tau_s`, s, for a step of
    /// `dt_s`, s (finite, > 0): one division.
    #[inline(always)]
    pub fn new(tau_s: f32, dt_s: f32) -> Self {
        let per_s = 1.0 / (tau_s + dt_s);
        DerivativeGain {
            step: dt_s * per_s,
            per_min: SECONDS_PER_MINUTE * per_s,
        }
    }
}

/// A first-order derivative filter's state: the smoothed signal S, in the
/// signal's unit (module docs).
#[repr(transparent)]
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct DerivativeFilter {
    smoothed: f32,
}

impl DerivativeFilter {
    /// A filter settled at `x`: its rate is 0 until the signal moves.
    #[inline(always)]
    pub const fn settled_at(x: f32) -> Self {
        DerivativeFilter { smoothed: x }
    }

    /// The smoothed signal S, in the signal's unit.
    #[inline(always)]
    pub const fn smoothed(self) -> f32 {
        self.smoothed
    }

    /// One sample `x`, `dt_s` seconds after the last, through a filter of
    /// time constant `tau_s`, s: the rate (x − S)/(τ + dt) per minute; S
    /// moves by dt times it (τ = 0: S becomes x exactly, the one-sample
    /// difference).
    #[inline(always)]
    pub fn update(&mut self, x: f32, tau_s: f32, dt_s: f32) -> f32 {
        let rate = (x - self.smoothed) / (tau_s + dt_s);
        self.smoothed = if tau_s == 0.0 { x } else { self.smoothed + dt_s * rate };
        rate * SECONDS_PER_MINUTE
    }

    /// [`Self::update`] with the gains computed once for several filters of
    /// one τ and dt: the rate per minute, `gain`'s 60/(τ + dt) times (x − S);
    /// S moves by dt/(τ + dt) of the difference.
    #[inline(always)]
    pub fn update_with(&mut self, x: f32, gain: DerivativeGain) -> f32 {
        let difference = x - self.smoothed;
        self.smoothed += gain.step * difference;
        gain.per_min * difference
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_step_reads_as_its_rate_through_either_form_and_the_state_moves_by_dt_over_tau_plus_dt() {
        let (tau_s, dt_s) = (10.0f32, 1.0f32);
        let mut divided = DerivativeFilter::settled_at(20.0);
        let mut multiplied = divided;
        // Exact: a steady signal has no rate at all.
        assert_eq!(divided.update(20.0, tau_s, dt_s).to_bits(), 0.0f32.to_bits());
        let rate = divided.update(21.0, tau_s, dt_s);
        assert!((rate - 60.0 / 11.0).abs() < 1e-5, "{rate}");
        assert!((divided.smoothed() - (20.0 + 1.0 / 11.0)).abs() < 1e-5);
        let gain = DerivativeGain::new(tau_s, dt_s);
        multiplied.update_with(20.0, gain);
        let rate_with = multiplied.update_with(21.0, gain);
        // The two forms agree to an f32 rounding or two, not bit for bit.
        assert!(
            (rate_with - rate).abs() <= 2.0 * f32::EPSILON * rate.abs(),
            "{rate_with} {rate}"
        );
        assert!((multiplied.smoothed() - divided.smoothed()).abs() <= 2.0 * f32::EPSILON * 21.0);
    }

    /// Every stored model was fitted with these two sequences of f32
    /// operations; a change to either changes the bits of its outputs.
    #[test]
    fn each_form_keeps_the_arithmetic_the_stored_models_were_fitted_with() {
        for tau_s in [0.0f32, 15.0, 60.0, 3840.0, 39_600.0] {
            for dt_s in [0.01f32, 0.37, 1.0] {
                let (mut filter, mut with_gain) =
                    (DerivativeFilter::settled_at(20.0), DerivativeFilter::settled_at(20.0));
                let (mut s_divided, mut s_multiplied) = (20.0f32, 20.0f32);
                let gain = DerivativeGain::new(tau_s, dt_s);
                for i in 0..200 {
                    let x = 20.0 + libm::sinf(i as f32 * 0.1) * 7.5;
                    // The feature sets' form: a division by τ + dt.
                    let rate = (x - s_divided) / (tau_s + dt_s);
                    s_divided = if tau_s == 0.0 { x } else { s_divided + dt_s * rate };
                    assert_eq!(filter.update(x, tau_s, dt_s).to_bits(), (rate * 60.0).to_bits());
                    assert_eq!(filter.smoothed().to_bits(), s_divided.to_bits());
                    // The response bank's form: the reciprocal shared by its signals.
                    let per_s = 1.0 / (tau_s + dt_s);
                    let d = x - s_multiplied;
                    s_multiplied += dt_s * per_s * d;
                    assert_eq!(with_gain.update_with(x, gain).to_bits(), (60.0 * per_s * d).to_bits());
                    assert_eq!(with_gain.smoothed().to_bits(), s_multiplied.to_bits());
                }
            }
        }
    }

    #[test]
    fn a_filter_without_time_constant_is_the_one_sample_difference() {
        let mut f = DerivativeFilter::settled_at(1.0);
        // Exact: 0.75, 0.5 and 60 are exact in f32, and S becomes x itself.
        assert_eq!(
            f.update(1.75, 0.0, 0.5).to_bits(),
            (0.75f32 / 0.5 * SECONDS_PER_MINUTE).to_bits()
        );
        assert_eq!(f.smoothed().to_bits(), 1.75f32.to_bits(), "S = x bit for bit");
    }
}
