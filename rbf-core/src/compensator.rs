//! The per-sample compensation step, shared by `trainer compensate` and the firmware.
//!
//! Per gyro sample: detect gaps, validate each thermometer the model reads
//! (holding its last good value through a sensor fault for a bounded time),
//! update the features, evaluate the model and subtract. Every sample yields exactly one
//! [`CompensatedSample`]; what went wrong is said in its [`Flags`].

use crate::axis::MAX_AXES;
use crate::features::{FeatureExtractor, FeatureVector, LOOP_THERMOMETER, THERMOMETERS};
use crate::flags::Flags;
use crate::model::Model;
use crate::shared_basis::SharedAxisModels;

/// Loop settings that belong to the deployment, not to the model.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CompensatorConfig {
    /// Nominal gyro sample period, s. A time step over twice this is a gap:
    /// the feature state restarts (recorded-run format).
    pub nominal_period_s: f32,
    /// How long the last good temperature may stand in for a failed sensor, s.
    /// Past this the output is uncompensated (flag 4) until the sensor recovers.
    pub max_temp_hold_s: f32,
    /// Lowest plausible loop temperature, °C (TMP117 range starts at −55 °C).
    pub min_plausible_temp_c: f32,
    /// Highest plausible loop temperature, °C (TMP117 range ends at 150 °C).
    pub max_plausible_temp_c: f32,
    /// Largest plausible |rate|, °/h; beyond it the sample is flagged invalid.
    pub max_abs_rate_dph: f32,
    /// Fastest plausible change of the loop temperature, °C/s. A reading that
    /// departs from the last good one by more than this times the elapsed
    /// time plus [`Self::temp_step_tolerance_c`] is a spike: treated as a
    /// sensor fault (flag 2, last good value held).
    pub max_temp_slew_c_per_s: f32,
    /// Allowance for sensor noise and quantisation in the spike test, °C.
    pub temp_step_tolerance_c: f32,
}

/// Largest |rate| a run may hold in `rate_dph` or `ref_dph`, °/h: 1000 °/s,
/// the compensator's plausible-rate limit (beyond it a live sample is
/// flagged invalid; a file holding one is refused by the run reader,
/// `record::MAX_ABS_RATE_DPH`).
pub const MAX_ABS_RATE_DPH: f64 = 3.6e6;

impl CompensatorConfig {
    /// Defaults for a gyro sampled at `sample_rate_hz`: 10 s temperature hold,
    /// −60 … 160 °C plausible, ±1000 °/s (3.6e6 °/h) plausible rate, spikes
    /// beyond 0.5 °C + 1 °C/s (twelve times the fastest chamber ramp of the
    /// papers, 5 °C/min) rejected.
    pub fn for_sample_rate(sample_rate_hz: f32) -> Self {
        CompensatorConfig {
            nominal_period_s: 1.0 / sample_rate_hz,
            max_temp_hold_s: 10.0,
            min_plausible_temp_c: -60.0,
            max_plausible_temp_c: 160.0,
            // The reader's limit (one number: what the unit flags 16, a run may not hold).
            max_abs_rate_dph: MAX_ABS_RATE_DPH as f32,
            max_temp_slew_c_per_s: 1.0,
            temp_step_tolerance_c: 0.5,
        }
    }

    /// Defaults for a recorded run whose nominal period is `period_s` (see
    /// [`crate::record::nominal_period_s`]); the same arithmetic on host and target.
    pub fn for_nominal_period_s(period_s: f64) -> Self {
        Self::for_sample_rate(Self::sample_rate_hz_for_period_s(period_s))
    }

    /// The sample rate, Hz, that [`Self::for_nominal_period_s`] gives
    /// [`Self::for_sample_rate`] for a run of nominal period `period_s`: what a
    /// loop set up by its sample rate (the C library's load) is given to agree.
    pub fn sample_rate_hz_for_period_s(period_s: f64) -> f32 {
        (1.0 / period_s) as f32
    }

    /// True when a time step of `dt_s` seconds breaks the run into a new segment.
    pub fn is_gap(&self, dt_s: f32) -> bool {
        !(dt_s > 0.0 && dt_s <= 2.0 * self.nominal_period_s)
    }

    fn is_plausible_temp(&self, temp_c: f32) -> bool {
        temp_c >= self.min_plausible_temp_c && temp_c <= self.max_plausible_temp_c
    }
}

/// The time step the compensator sees between two recorded sample times, s:
/// the f64 difference rounded once to f32 (0 for the first row).
pub fn time_step_s(prev_time_s: Option<f64>, time_s: f64) -> f32 {
    prev_time_s.map_or(0.0, |p| (time_s - p) as f32)
}

/// One gyro sample as it arrives.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GyroSample {
    /// Time since the previous sample, s (ignored on the very first sample).
    pub dt_s: f32,
    /// Gyro output, °/h.
    pub rate_dph: f32,
    /// Thermometer readings `temp_a` … `temp_h`, °C; `None` where a sensor
    /// failed to answer or is not fitted. Index [`LOOP_THERMOMETER`]
    /// (`temp_c`) is the fiber-loop sensor single-point models read.
    pub temps_c: [Option<f32>; THERMOMETERS],
}

impl GyroSample {
    /// A sample with the loop temperature only (single-point models).
    pub const fn new(dt_s: f32, rate_dph: f32, temp_c: Option<f32>) -> Self {
        let mut temps_c = [None; THERMOMETERS];
        temps_c[LOOP_THERMOMETER] = temp_c;
        GyroSample {
            dt_s,
            rate_dph,
            temps_c,
        }
    }

    /// The fiber-loop temperature, °C, if the sensor answered.
    pub const fn temp_c(&self) -> Option<f32> {
        self.temps_c[LOOP_THERMOMETER]
    }

    /// The sample the compensator sees for a recorded row, as the firmware
    /// receives it: the time step since the previous row (computed in f64,
    /// rounded once to f32, on host and target alike; 0 for the first row),
    /// the rate rounded to f32 (the front end's binary32 word), and every
    /// thermometer at TMP117 resolution (1/128 °C, the finest the firmware
    /// can see). A reading is `None` when the sensor failed or the run has
    /// no such column.
    pub fn from_recorded(
        prev_time_s: Option<f64>,
        time_s: f64,
        rate_dph: f64,
        temps_c: &[Option<f64>; THERMOMETERS],
    ) -> Self {
        GyroSample {
            dt_s: time_step_s(prev_time_s, time_s),
            rate_dph: rate_dph as f32,
            temps_c: temps_c.map(|t| t.map(crate::sensor::tmp117_quantise)),
        }
    }
}

/// One output sample: always produced, whatever the inputs were.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CompensatedSample {
    /// Bias estimate subtracted, °/h (0 when uncompensated).
    pub bias_dph: f32,
    /// `rate_dph − bias_dph`, °/h.
    pub rate_comp_dph: f32,
    /// Temperature the features used (held value during a fault), °C; NaN if
    /// none: the loop sensor's, or for a multi-point model its reference
    /// thermometer's ([`crate::FeatureSet::reference_thermometer`]).
    pub temp_c: f32,
    /// What went wrong, if anything.
    pub flags: Flags,
}

/// Features of one sample plus the flags raised while computing them.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FeatureFrame {
    /// The model inputs; `None` when no usable temperature is available.
    pub features: Option<FeatureVector>,
    /// Flags raised so far (sensor fault, warm-up, no valid model).
    pub flags: Flags,
}

/// Fault state of one thermometer: its last good reading and how long that
/// has been standing in.
#[derive(Clone, Copy, Debug, Default)]
struct Channel {
    last_good_c: Option<f32>,
    fault_hold_s: f32,
}

/// What one thermometer contributes to a sample.
enum Reading {
    /// A plausible reading within reach of the last good one, °C.
    Fresh(f32),
    /// The sensor failed; its last good value stands in, °C.
    Held(f32),
    /// The sensor failed and there is no value (held too long, or never one).
    Expired,
}

impl Channel {
    const NEW: Channel = Channel {
        last_good_c: None,
        fault_hold_s: 0.0,
    };

    /// Judges a reading `elapsed_s` after the previous sample. A reading is
    /// good when plausible and, unless the features start afresh anyway
    /// (`fresh_start`), within reach of the last good one (no spike).
    fn accept(
        &mut self,
        reading: Option<f32>,
        config: &CompensatorConfig,
        elapsed_s: f32,
        fresh_start: bool,
    ) -> Reading {
        let since_good_s = self.fault_hold_s + elapsed_s;
        let reachable = |t: f32| match self.last_good_c {
            Some(last) if !fresh_start => {
                (t - last).abs() <= config.temp_step_tolerance_c + config.max_temp_slew_c_per_s * since_good_s
            }
            _ => true,
        };
        match reading
            .filter(|&t| config.is_plausible_temp(t))
            .filter(|&t| reachable(t))
        {
            Some(t) => {
                self.last_good_c = Some(t);
                self.fault_hold_s = 0.0;
                Reading::Fresh(t)
            }
            None => {
                self.fault_hold_s += elapsed_s;
                match self.last_good_c {
                    Some(held) if self.fault_hold_s <= config.max_temp_hold_s => Reading::Held(held),
                    _ => Reading::Expired,
                }
            }
        }
    }
}

/// Running state of the compensation loop (the model is passed by reference).
#[derive(Clone, Copy, Debug, Default)]
pub struct Compensator {
    extractor: FeatureExtractor,
    channels: [Channel; THERMOMETERS],
    restart_pending: bool,
    started: bool,
}

impl Compensator {
    /// A fresh loop: the first sample starts a segment.
    pub const fn new() -> Self {
        Compensator {
            extractor: FeatureExtractor::new(),
            channels: [Channel::NEW; THERMOMETERS],
            restart_pending: false,
            started: false,
        }
    }

    /// Computes the features of one sample (the training path uses this directly).
    pub fn features(
        &mut self,
        model_features: &crate::FeatureConfig,
        config: &CompensatorConfig,
        sample: &GyroSample,
    ) -> FeatureFrame {
        let mut flags = Flags::NONE;
        let gap = !self.started || config.is_gap(sample.dt_s);
        self.started = true;
        if gap {
            self.extractor.restart();
        }
        let elapsed_s = if sample.dt_s.is_finite() && sample.dt_s > 0.0 {
            sample.dt_s
        } else {
            0.0
        };

        // Each thermometer the model reads, in index order (set bits only).
        let fresh_start = gap || self.restart_pending;
        let mut temps_c = [0.0f32; THERMOMETERS];
        let mut expired = false;
        let mut unvisited = model_features.set.thermometers().bits();
        while unvisited != 0 {
            let i = unvisited.trailing_zeros() as usize;
            unvisited &= unvisited - 1;
            let (Some(channel), Some(slot), Some(&reading)) =
                (self.channels.get_mut(i), temps_c.get_mut(i), sample.temps_c.get(i))
            else {
                continue;
            };
            match channel.accept(reading, config, elapsed_s, fresh_start) {
                Reading::Fresh(t) => *slot = t,
                Reading::Held(t) => {
                    flags |= Flags::TEMP_SENSOR_FAULT;
                    *slot = t;
                }
                Reading::Expired => {
                    flags |= Flags::TEMP_SENSOR_FAULT;
                    expired = true;
                }
            }
        }
        if expired {
            // Held too long (or never had a value): stop compensating and start
            // the features afresh once every sensor has a value again.
            self.restart_pending = true;
            return FeatureFrame {
                features: None,
                flags: flags | Flags::NO_VALID_MODEL,
            };
        }
        if self.restart_pending {
            self.restart_pending = false;
            self.extractor.restart();
        }
        let dt_s = if gap { 0.0 } else { sample.dt_s };
        let features = self.extractor.update(model_features, dt_s, &temps_c);
        if features.warming_up {
            flags |= Flags::WARMING_UP;
        }
        FeatureFrame {
            features: Some(features),
            flags,
        }
    }

    /// Compensates one sample. `model = None` (absent or invalid blob) passes the
    /// rate through with flag 4 while still tracking temperature faults.
    ///
    pub fn process(
        &mut self,
        model: Option<&Model>,
        config: &CompensatorConfig,
        sample: &GyroSample,
    ) -> CompensatedSample {
        self.process_with(model, config, sample)
    }

    /// [`Self::process`] with a model of any centre capacity `K`: a
    /// multi-axis IMU runs one compensator per axis, each with its axis's
    /// model ([`crate::blob::axes::AxisModels::get`]) and samples, through
    /// this same step.
    pub fn process_with<const K: usize>(
        &mut self,
        model: Option<&Model<K>>,
        config: &CompensatorConfig,
        sample: &GyroSample,
    ) -> CompensatedSample {
        const NO_FEATURES: crate::FeatureConfig = crate::FeatureConfig::single(crate::FeatureSet::Temp, 0.0);
        let feature_config = model.map_or(&NO_FEATURES, |m| m.features());
        let frame = self.features(feature_config, config, sample);
        let mut flags = frame.flags;
        if !(sample.rate_dph.is_finite() && sample.rate_dph.abs() <= config.max_abs_rate_dph) {
            flags |= Flags::RATE_INVALID;
        }
        let temp_c = frame.features.map_or(f32::NAN, |f| f.temp_c());
        let evaluation = match (model, frame.features) {
            (Some(model), Some(features)) => {
                let evaluation = model.eval(&features);
                Some((evaluation.bias_dph, evaluation.clamped))
            }
            _ => None,
        };
        finish_sample(flags, sample.rate_dph, temp_c, evaluation)
    }

    /// The step of a shared-basis multi-axis model
    /// ([`crate::shared_basis::SharedAxisModels`]): the axes share one
    /// thermometer set, so one compensator computes the features once, the
    /// model evaluates every axis's bias from them, and each axis's rate
    /// (x first, `rates_dph`) is checked and compensated as
    /// [`Self::process_with`] does it. An axis without a layer, or every
    /// axis when `models` is `None`, passes its rate through with flag 4.
    pub fn process_shared<const K: usize>(
        &mut self,
        models: Option<&SharedAxisModels<K>>,
        config: &CompensatorConfig,
        dt_s: f32,
        temps_c: &[Option<f32>; THERMOMETERS],
        rates_dph: &[f32; MAX_AXES],
    ) -> [CompensatedSample; MAX_AXES] {
        const NO_FEATURES: crate::FeatureConfig = crate::FeatureConfig::single(crate::FeatureSet::Temp, 0.0);
        let feature_config = models.map_or(&NO_FEATURES, |m| m.features());
        let sample = GyroSample {
            dt_s,
            rate_dph: 0.0,
            temps_c: *temps_c,
        };
        let frame = self.features(feature_config, config, &sample);
        let temp_c = frame.features.map_or(f32::NAN, |f| f.temp_c());
        let evaluation = match (models, frame.features) {
            (Some(models), Some(features)) => Some((models.eval_axes(&features), models.mask())),
            _ => None,
        };
        core::array::from_fn(|a| {
            let mut flags = frame.flags;
            let rate_dph = rates_dph.get(a).copied().unwrap_or(f32::NAN);
            if !(rate_dph.is_finite() && rate_dph.abs() <= config.max_abs_rate_dph) {
                flags |= Flags::RATE_INVALID;
            }
            let axis = evaluation.and_then(|(e, mask)| {
                (mask & (1 << a) != 0).then(|| (e.bias_dph.get(a).copied().unwrap_or(f32::NAN), e.clamped))
            });
            finish_sample(flags, rate_dph, temp_c, axis)
        })
    }
}

/// The end of a step: the bias subtracted when the model gave one
/// (`evaluation`: bias, °/h, and whether an input was clamped), else the
/// rate passed through with flag 4.
#[inline(always)]
fn finish_sample(mut flags: Flags, rate_dph: f32, temp_c: f32, evaluation: Option<(f32, bool)>) -> CompensatedSample {
    let bias_dph = match evaluation {
        Some((bias_dph, clamped)) => {
            if clamped {
                flags |= Flags::INPUT_CLAMPED;
            }
            if bias_dph.is_finite() {
                bias_dph
            } else {
                // Unreachable for a validated model (its output bound is
                // checked); kept so the output stays finite regardless.
                flags |= Flags::NO_VALID_MODEL;
                0.0
            }
        }
        None => {
            flags |= Flags::NO_VALID_MODEL;
            0.0
        }
    };
    CompensatedSample {
        bias_dph,
        rate_comp_dph: rate_dph - bias_dph,
        temp_c,
        flags,
    }
}

#[cfg(test)]
#[allow(
    clippy::float_cmp,
    reason = "expected values are exact in binary floating point; exactness is what these tests guard"
)]
mod tests {
    use super::*;
    use crate::model::{ModelBody, ModelInfo};
    use crate::poly::Poly3;
    use crate::{FeatureConfig, FeatureSet};

    fn linear_in_t() -> Model {
        let cfg = FeatureConfig::single(FeatureSet::Temp, 0.0);
        let body = ModelBody::Poly3(Poly3::new(0.0, [0.0, 1.0, 0.0, 0.0]).unwrap());
        Model::new(cfg, &[(-50.0, 100.0)], body, ModelInfo::default()).unwrap()
    }

    fn sample(temp_c: Option<f32>) -> GyroSample {
        GyroSample::new(1.0, 100.0, temp_c)
    }

    #[test]
    fn subtracts_the_model_bias() {
        let model = linear_in_t();
        let cfg = CompensatorConfig::for_sample_rate(1.0);
        let mut comp = Compensator::new();
        let out = comp.process(Some(&model), &cfg, &sample(Some(25.0)));
        assert_eq!(out.bias_dph, 25.0);
        assert_eq!(out.rate_comp_dph, 75.0);
    }

    #[test]
    fn sensor_fault_holds_the_last_good_value_then_gives_up_until_recovery() {
        let model = linear_in_t();
        let mut cfg = CompensatorConfig::for_sample_rate(1.0);
        cfg.max_temp_hold_s = 3.0;
        let mut comp = Compensator::new();
        comp.process(Some(&model), &cfg, &sample(Some(30.0)));
        for _ in 0..3 {
            let held = comp.process(Some(&model), &cfg, &sample(None));
            assert_eq!(held.bias_dph, 30.0);
            assert!(held.flags.contains(Flags::TEMP_SENSOR_FAULT));
            assert!(!held.flags.contains(Flags::NO_VALID_MODEL));
        }
        let expired = comp.process(Some(&model), &cfg, &sample(Some(f32::NAN)));
        assert_eq!(expired.flags, Flags::TEMP_SENSOR_FAULT | Flags::NO_VALID_MODEL);
        assert_eq!(expired.rate_comp_dph, 100.0, "uncompensated once the hold has expired");
        let recovered = comp.process(Some(&model), &cfg, &sample(Some(31.0)));
        assert_eq!(recovered.bias_dph, 31.0);
        assert!(
            recovered.flags.contains(Flags::WARMING_UP),
            "features restart after recovery"
        );
    }

    #[test]
    fn temperature_spikes_are_faults_but_a_lasting_step_is_accepted_after_the_hold() {
        let model = linear_in_t();
        let mut cfg = CompensatorConfig::for_sample_rate(1.0);
        cfg.max_temp_hold_s = 3.0;
        let mut comp = Compensator::new();
        comp.process(Some(&model), &cfg, &sample(Some(20.0)));
        let spike = comp.process(Some(&model), &cfg, &sample(Some(45.0)));
        assert_eq!(spike.flags, Flags::TEMP_SENSOR_FAULT);
        assert_eq!(spike.bias_dph, 20.0, "the last good value stands in");
        // 2 s after the last good reading, 2.4 °C away: within 0.5 + 1 °C/s × 2 s.
        let ok = comp.process(Some(&model), &cfg, &sample(Some(22.4)));
        assert_eq!((ok.flags, ok.bias_dph), (Flags::NONE, 22.4));
        // A real step the sensor keeps reporting: faults through the hold, then accepted afresh.
        let mut flags = [Flags::NONE; 6];
        for f in &mut flags {
            *f = comp.process(Some(&model), &cfg, &sample(Some(40.0))).flags;
        }
        assert_eq!(flags[..3], [Flags::TEMP_SENSOR_FAULT; 3]);
        assert_eq!(flags[3], Flags::TEMP_SENSOR_FAULT | Flags::NO_VALID_MODEL);
        assert!(flags[4].contains(Flags::WARMING_UP) && !flags[4].contains(Flags::TEMP_SENSOR_FAULT));
    }

    #[test]
    fn implausible_temperatures_count_as_faults() {
        let model = linear_in_t();
        let cfg = CompensatorConfig::for_sample_rate(1.0);
        let mut comp = Compensator::new();
        comp.process(Some(&model), &cfg, &sample(Some(20.0)));
        let out = comp.process(Some(&model), &cfg, &sample(Some(-273.0)));
        assert!(out.flags.contains(Flags::TEMP_SENSOR_FAULT));
        assert_eq!(out.bias_dph, 20.0);
    }

    #[test]
    fn no_model_or_no_temperature_passes_the_rate_through_with_flag_4() {
        let cfg = CompensatorConfig::for_sample_rate(1.0);
        let mut comp = Compensator::new();
        let out = comp.process(None, &cfg, &sample(Some(20.0)));
        assert_eq!((out.bias_dph, out.rate_comp_dph), (0.0, 100.0));
        assert!(out.flags.contains(Flags::NO_VALID_MODEL));
        let model = linear_in_t();
        let mut comp = Compensator::new();
        let out = comp.process(Some(&model), &cfg, &sample(None));
        assert_eq!(out.flags, Flags::TEMP_SENSOR_FAULT | Flags::NO_VALID_MODEL);
    }

    #[test]
    fn invalid_rates_are_passed_through_and_flagged() {
        let model = linear_in_t();
        let cfg = CompensatorConfig::for_sample_rate(1.0);
        let mut comp = Compensator::new();
        for rate in [f32::NAN, f32::INFINITY, 1e9] {
            let out = comp.process(Some(&model), &cfg, &GyroSample::new(1.0, rate, Some(20.0)));
            assert!(out.flags.contains(Flags::RATE_INVALID), "rate {rate}");
            assert!(out.bias_dph.is_finite());
        }
    }

    #[test]
    fn multipoint_models_watch_each_thermometer_they_read_and_only_those() {
        use crate::features::{Probe, Probes};
        // Inputs temp_a and temp_c − temp_e; temp_h is fitted but unused.
        let probes = Probes::new(&[Probe::Temp(0), Probe::Gradient(2, 4)]).unwrap();
        let model_features = FeatureConfig::multipoint(probes);
        let mut cfg = CompensatorConfig::for_sample_rate(1.0);
        cfg.max_temp_hold_s = 2.0;
        let mut comp = Compensator::new();
        let with = |a: Option<f32>, e: Option<f32>, h: Option<f32>| {
            let mut s = GyroSample::new(1.0, 0.0, Some(22.0));
            (s.temps_c[0], s.temps_c[4], s.temps_c[7]) = (a, e, h);
            s
        };
        let inputs = |frame: FeatureFrame| frame.features.map(|f| [f.as_slice()[0], f.as_slice()[1]]);
        let first = comp.features(&model_features, &cfg, &with(Some(20.0), Some(21.0), None));
        assert_eq!(inputs(first), Some([20.0, 1.0]));
        assert!(!first.flags.contains(Flags::TEMP_SENSOR_FAULT), "temp_h is not read");
        // temp_e fails: its last good value stands in while temp_a moves on.
        let held = comp.features(&model_features, &cfg, &with(Some(20.5), None, None));
        assert_eq!(inputs(held), Some([20.5, 1.0]));
        assert_eq!(held.flags, Flags::TEMP_SENSOR_FAULT);
        // A spike on temp_a alone is a fault of temp_a alone.
        let spike = comp.features(&model_features, &cfg, &with(Some(60.0), Some(21.0), None));
        assert_eq!(inputs(spike), Some([20.5, 1.0]));
        assert_eq!(spike.flags, Flags::TEMP_SENSOR_FAULT);
        // temp_e fails for longer than the 2-s hold: no features until it
        // answers again, then a fresh start.
        for _ in 0..2 {
            let within = comp.features(&model_features, &cfg, &with(Some(20.5), None, None));
            assert!(within.features.is_some());
        }
        let expired = comp.features(&model_features, &cfg, &with(Some(20.5), None, None));
        assert_eq!(expired.features, None);
        assert_eq!(expired.flags, Flags::TEMP_SENSOR_FAULT | Flags::NO_VALID_MODEL);
        let back = comp.features(&model_features, &cfg, &with(Some(20.5), Some(23.0), None));
        assert_eq!(inputs(back), Some([20.5, -1.0]));
        assert_eq!(back.flags, Flags::WARMING_UP, "the features restart after recovery");
    }

    #[test]
    fn a_gap_restarts_the_features() {
        let cfg_model = FeatureConfig::single(FeatureSet::TempRate, 0.0);
        let cfg = CompensatorConfig::for_sample_rate(1.0);
        let mut comp = Compensator::new();
        comp.features(&cfg_model, &cfg, &sample(Some(20.0)));
        let step = comp.features(&cfg_model, &cfg, &sample(Some(21.0))).features.unwrap();
        assert_eq!(step.as_slice()[1], 60.0, "1 °C in 1 s is 60 °C/min");
        let after_gap = GyroSample::new(2.5, 0.0, Some(30.0));
        let frame = comp.features(&cfg_model, &cfg, &after_gap);
        assert_eq!(frame.features.unwrap().as_slice()[1], 0.0);
        assert!(frame.flags.contains(Flags::WARMING_UP));
    }
}
