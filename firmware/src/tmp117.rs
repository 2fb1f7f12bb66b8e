//! Minimal TMP117 driver (embedded-hal 1.0 I2C): identity check, continuous
//! conversion, non-blocking read of the temperature result register.
//!
//! The `tmp117` crate targets embedded-hal 1.0 too, but its high-level API
//! blocks in `wait_temp` inside mode closures and converts to °C itself; the
//! sample loop needs a register read that never waits and the conversion it
//! shares with the trainer ([`rbf_core::sensor::tmp117_celsius`]).

use embedded_hal::i2c::I2c;
use rbf_core::sensor::tmp117_celsius;

use crate::sensors::{SensorFault, Thermometer};

/// Temperature result register (i16, 7.8125 m°C/LSB).
pub const REG_TEMP_RESULT: u8 = 0x00;
/// Configuration register.
pub const REG_CONFIGURATION: u8 = 0x01;
/// Device ID register; bits 11..0 read 0x117.
pub const REG_DEVICE_ID: u8 = 0x0F;
/// Expected device ID (bits 11..0).
pub const DEVICE_ID: u16 = 0x0117;
/// Continuous conversion, 8 averages, no standby: a new result every 125 ms.
pub const CONFIG_CONTINUOUS_AVG8: u16 = 0x0020;
/// Address with ADD0 to GND; 0x49 (V+), 0x4A (SDA), 0x4B (SCL) are the others.
pub const DEFAULT_ADDRESS: u8 = 0x48;

/// Driver errors: the bus error or a device that is not a TMP117.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Error<E> {
    /// I2C transaction failed.
    I2c(E),
    /// The device ID register read this instead of 0x117.
    WrongDevice(u16),
}

/// A TMP117 on an I2C bus it owns (give it back with [`Tmp117::destroy`]).
#[derive(Debug)]
pub struct Tmp117<I2C> {
    i2c: I2C,
    address: u8,
}

impl<I2C: I2c> Tmp117<I2C> {
    /// A driver for the TMP117 at `address`; no bus traffic yet.
    pub fn new(i2c: I2C, address: u8) -> Self {
        Tmp117 { i2c, address }
    }

    fn read_register(&mut self, register: u8) -> Result<u16, Error<I2C::Error>> {
        let mut buf = [0u8; 2];
        self.i2c
            .write_read(self.address, &[register], &mut buf)
            .map_err(Error::I2c)?;
        Ok(u16::from_be_bytes(buf))
    }

    /// Checks the device ID and starts continuous conversion.
    pub fn init(&mut self) -> Result<(), Error<I2C::Error>> {
        let id = self.read_register(REG_DEVICE_ID)? & 0x0FFF;
        if id != DEVICE_ID {
            return Err(Error::WrongDevice(id));
        }
        let [hi, lo] = CONFIG_CONTINUOUS_AVG8.to_be_bytes();
        self.i2c
            .write(self.address, &[REG_CONFIGURATION, hi, lo])
            .map_err(Error::I2c)
    }

    /// The latest conversion result, raw register value.
    pub fn read_raw(&mut self) -> Result<i16, Error<I2C::Error>> {
        self.read_register(REG_TEMP_RESULT).map(|v| v as i16)
    }

    /// Gives the bus back.
    pub fn destroy(self) -> I2C {
        self.i2c
    }
}

impl<I2C: I2c> Thermometer for Tmp117<I2C> {
    fn read_temp_c(&mut self) -> Result<f32, SensorFault> {
        self.read_raw().map(tmp117_celsius).map_err(|e| match e {
            Error::I2c(_) => SensorFault::Bus,
            Error::WrongDevice(_) => SensorFault::WrongDevice,
        })
    }
}

#[cfg(test)]
#[allow(clippy::float_cmp, reason = "TMP117 codes convert exactly")]
mod tests {
    use super::*;
    use embedded_hal::i2c::ErrorKind;
    use embedded_hal_mock::eh1::i2c::{Mock, Transaction};

    #[test]
    fn init_checks_identity_and_starts_continuous_conversion() {
        let expectations = [
            Transaction::write_read(0x48, vec![REG_DEVICE_ID], vec![0x01, 0x17]),
            Transaction::write(0x48, vec![REG_CONFIGURATION, 0x00, 0x20]),
        ];
        let mut tmp = Tmp117::new(Mock::new(&expectations), 0x48);
        tmp.init().unwrap();
        tmp.destroy().done();
    }

    #[test]
    fn init_refuses_another_device() {
        let expectations = [Transaction::write_read(0x49, vec![REG_DEVICE_ID], vec![0x02, 0x75])];
        let mut tmp = Tmp117::new(Mock::new(&expectations), 0x49);
        assert_eq!(tmp.init(), Err(Error::WrongDevice(0x275)));
        tmp.destroy().done();
    }

    #[test]
    fn reads_temperature_and_reports_a_nack_as_a_bus_fault() {
        let expectations = [
            Transaction::write_read(0x48, vec![REG_TEMP_RESULT], vec![0x0C, 0x80]),
            Transaction::write_read(0x48, vec![REG_TEMP_RESULT], vec![0xFF, 0xFF]),
            Transaction::write_read(0x48, vec![REG_TEMP_RESULT], vec![0, 0]).with_error(ErrorKind::NoAcknowledge(
                embedded_hal::i2c::NoAcknowledgeSource::Address,
            )),
        ];
        let mut tmp = Tmp117::new(Mock::new(&expectations), 0x48);
        assert_eq!(tmp.read_temp_c(), Ok(25.0));
        assert_eq!(tmp.read_temp_c(), Ok(-0.007_812_5));
        assert_eq!(tmp.read_temp_c(), Err(SensorFault::Bus));
        tmp.destroy().done();
    }
}
