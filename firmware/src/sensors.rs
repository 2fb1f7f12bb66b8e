//! What the compensation loop needs from its sensors, independent of buses:
//! per axis, its thermometers ([`AxisThermometers`]) and its rate front end
//! ([`AxisFrontEnds`]). A single gyro's sensors are the one axis x; an
//! IMU's are an array, one per axis, x first.

use rbf_core::axis::Axis;
use rbf_core::features::{LOOP_THERMOMETER, THERMOMETERS, ThermometerSet};

/// Why a sensor produced no usable value this time.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum SensorFault {
    /// The bus transaction failed (NACK, arbitration loss, SPI error).
    Bus,
    /// The data arrived but failed its integrity check (CRC).
    Integrity,
    /// The device answered with an unexpected identity.
    WrongDevice,
    /// The device has not answered its initialisation yet (it is retried).
    NotReady,
    /// The device had no new sample (its sample counter did not move).
    Stale,
    /// A wait on the bus ran out of time; the bus was recovered.
    Timeout,
}

/// A loop thermometer: one temperature in °C per successful read.
pub trait Thermometer {
    /// Reads the latest fiber-loop temperature, °C.
    fn read_temp_c(&mut self) -> Result<f32, SensorFault>;
}

/// Readings of thermometers `temp_a` … `temp_h`, °C, in index order
/// (`None`: the read failed or the thermometer was not read).
pub type Readings = [Option<f32>; THERMOMETERS];

/// The thermometers the loop reads: a single fiber-loop sensor (any
/// [`Thermometer`]) or an array of them ([`crate::tmp117::Tmp117Array`]).
pub trait Thermometers {
    /// Reads the thermometers of `wanted` (bit i = thermometer i) into
    /// `readings`, `None` where a read failed and for those not wanted;
    /// returns how many wanted thermometers gave no reading.
    fn read_wanted(&mut self, wanted: u8, readings: &mut Readings) -> u32;
}

/// A single loop sensor is thermometer c (`temp_c`), whatever the model wants:
/// wanted thermometers it cannot provide stay `None` and count as failed.
impl<T: Thermometer> Thermometers for T {
    fn read_wanted(&mut self, wanted: u8, readings: &mut Readings) -> u32 {
        *readings = [None; THERMOMETERS];
        let loop_bit = ThermometerSet::LOOP.bits();
        if wanted & loop_bit != 0 {
            readings[LOOP_THERMOMETER] = self.read_temp_c().ok();
        }
        let provided = if readings[LOOP_THERMOMETER].is_some() {
            loop_bit
        } else {
            0
        };
        (wanted & !provided).count_ones()
    }
}

/// One sample from the gyro front end.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RateSample {
    /// Rate, °/h.
    pub rate_dph: f32,
    /// The front end vouches for the sample (valid, in range, loop locked).
    pub valid: bool,
}

/// The gyro's rate front end.
pub trait RateFrontEnd {
    /// Reads the sample that data-ready announced.
    fn read_rate(&mut self) -> Result<RateSample, SensorFault>;
}

/// The thermometers of every axis the loop runs: each axis's loop
/// thermometer (its coil sensor) as `temp_c`, plus whatever shared
/// thermometers its model reads.
pub trait AxisThermometers {
    /// Reads the thermometers of `wanted` (bit i = thermometer i) for
    /// `axis` into `readings` (`None` where a read failed and for those not
    /// wanted); returns how many wanted thermometers gave no reading.
    fn read_axis(&mut self, axis: Axis, wanted: u8, readings: &mut Readings) -> u32;
}

/// A single gyro's thermometers: the one axis (the loop asks for axis x only).
impl<T: Thermometers> AxisThermometers for T {
    #[inline(always)]
    fn read_axis(&mut self, _axis: Axis, wanted: u8, readings: &mut Readings) -> u32 {
        self.read_wanted(wanted, readings)
    }
}

/// One thermometer set per axis, x first; an axis beyond the array reads
/// nothing (every wanted thermometer failed).
impl<T: Thermometers, const N: usize> AxisThermometers for [T; N] {
    fn read_axis(&mut self, axis: Axis, wanted: u8, readings: &mut Readings) -> u32 {
        match self.get_mut(axis.index()) {
            Some(t) => t.read_wanted(wanted, readings),
            None => {
                *readings = [None; THERMOMETERS];
                wanted.count_ones()
            }
        }
    }
}

/// The rate front ends of every axis the loop runs.
pub trait AxisFrontEnds {
    /// Reads `axis`'s sample that data-ready announced.
    fn read_axis_rate(&mut self, axis: Axis) -> Result<RateSample, SensorFault>;
}

/// A single gyro's front end: the one axis (the loop asks for axis x only).
impl<R: RateFrontEnd> AxisFrontEnds for R {
    #[inline(always)]
    fn read_axis_rate(&mut self, _axis: Axis) -> Result<RateSample, SensorFault> {
        self.read_rate()
    }
}

/// One front end per axis, x first; an axis beyond the array fails its read.
impl<R: RateFrontEnd, const N: usize> AxisFrontEnds for [R; N] {
    fn read_axis_rate(&mut self, axis: Axis) -> Result<RateSample, SensorFault> {
        self.get_mut(axis.index())
            .map_or(Err(SensorFault::Bus), RateFrontEnd::read_rate)
    }
}
