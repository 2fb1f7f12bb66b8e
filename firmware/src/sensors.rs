//! What the compensation loop needs from its sensors, independent of buses.

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
}

/// A loop thermometer: one temperature in °C per successful read.
pub trait Thermometer {
    /// Reads the latest fiber-loop temperature, °C.
    fn read_temp_c(&mut self) -> Result<f32, SensorFault>;
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
