//! Minimal TMP117 driver (embedded-hal 1.0 I2C): identity check, continuous
//! conversion, non-blocking read of the temperature result register; and
//! [`Tmp117Array`], up to eight of them on two buses for multi-point models.
//!
//! The `tmp117` crate targets embedded-hal 1.0 too, but its high-level API
//! blocks in `wait_temp` inside mode closures and converts to °C itself; the
//! sample loop needs a register read that never waits and the conversion it
//! shares with the trainer ([`rbf_core::sensor::tmp117_celsius`]).

use embedded_hal::i2c::I2c;
use rbf_core::features::THERMOMETERS;
use rbf_core::sensor::tmp117_celsius;

use crate::sensors::{Readings, SensorFault, Thermometer};

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
/// The four addresses a TMP117 can take (ADD0 to GND, V+, SDA, SCL): four per bus.
pub const ADDRESSES: [u8; 4] = [0x48, 0x49, 0x4A, 0x4B];
/// Thermometers per bus.
pub const PER_BUS: usize = ADDRESSES.len();

/// Driver errors: the bus error or a device that is not a TMP117.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Error<E> {
    /// I2C transaction failed.
    I2c(E),
    /// The device ID register read this instead of 0x117.
    WrongDevice(u16),
}

/// TEMP_RESULT's power-on value (−256 °C): no conversion has finished yet.
pub const RESULT_NOT_CONVERTED: i16 = i16::MIN;

/// A TMP117 on an I2C bus it owns (give it back with [`Tmp117::destroy`]).
///
/// Until it has answered [`Tmp117::init`], each
/// [`Thermometer::read_temp_c`] tries the init again first (a sensor that
/// powers up late, or a bus that was stuck, is picked up when it answers);
/// the reads fail meanwhile and the loop flags them. A result register
/// back at its power-on value ([`RESULT_NOT_CONVERTED`]) after it had
/// converted means the sensor reset on its own (a brown-out): it is
/// initialised again the same way.
#[derive(Debug)]
pub struct Tmp117<I2C> {
    i2c: I2C,
    address: u8,
    ready: bool,
    /// A conversion result was read since the last init.
    converted: bool,
}

impl<I2C: I2c> Tmp117<I2C> {
    /// A driver for the TMP117 at `address`; no bus traffic yet.
    pub fn new(i2c: I2C, address: u8) -> Self {
        Tmp117 {
            i2c,
            address,
            ready: false,
            converted: false,
        }
    }

    /// A driver for a TMP117 already initialised (the array keeps that state itself).
    fn started(i2c: I2C, address: u8) -> Self {
        Tmp117 {
            i2c,
            address,
            ready: true,
            converted: false,
        }
    }

    /// Whether the sensor answered its init.
    pub fn is_ready(&self) -> bool {
        self.ready
    }

    fn read_register(&mut self, register: u8) -> Result<u16, Error<I2C::Error>> {
        let mut buf = [0u8; 2];
        self.i2c
            .write_read(self.address, &[register], &mut buf)
            .map_err(Error::I2c)?;
        Ok(u16::from_be_bytes(buf))
    }

    /// Checks the device ID and starts continuous conversion.
    #[inline(never)]
    pub fn init(&mut self) -> Result<(), Error<I2C::Error>> {
        let id = self.read_register(REG_DEVICE_ID)? & 0x0FFF;
        if id != DEVICE_ID {
            return Err(Error::WrongDevice(id));
        }
        let [hi, lo] = CONFIG_CONTINUOUS_AVG8.to_be_bytes();
        self.i2c
            .write(self.address, &[REG_CONFIGURATION, hi, lo])
            .map_err(Error::I2c)?;
        self.ready = true;
        self.converted = false;
        Ok(())
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
        let fault = |e: Error<I2C::Error>| match e {
            Error::I2c(_) => SensorFault::Bus,
            Error::WrongDevice(_) => SensorFault::WrongDevice,
        };
        if !self.ready {
            self.init().map_err(|e| match e {
                Error::I2c(_) => SensorFault::NotReady,
                other => fault(other),
            })?;
        }
        match self.read_raw().map_err(fault)? {
            RESULT_NOT_CONVERTED => {
                // The power-on value after a conversion was read: the
                // sensor went through a reset of its own (a brown-out) and
                // runs its power-on configuration (a result a second): it
                // is initialised again on the next read. Before the first
                // conversion it is the value a late sensor still reads.
                if self.converted {
                    self.ready = false;
                }
                Err(SensorFault::NotReady)
            }
            raw => {
                self.converted = true;
                Ok(tmp117_celsius(raw))
            }
        }
    }
}

/// Up to eight TMP117s on two I2C buses, four addresses each, for
/// multi-point models: bus 1 carries `temp_a` … `temp_d` at 0x48 … 0x4B
/// ([`ADDRESSES`] in order), bus 2 `temp_e` … `temp_h`. `temp_c` (bus 1,
/// 0x4A) is the fiber-loop sensor single-point models read.
///
/// Only the thermometers the model reads are read on a sample (bus time is
/// the loop's budget); one that is not fitted, failed its identity check or
/// does not answer gives `None` for that sample, and rbf-core holds its last
/// good value.
#[derive(Debug)]
pub struct Tmp117Array<B1, B2> {
    bus1: B1,
    bus2: B2,
    fitted: u8,
    /// Thermometers mounted but not yet answering: their init is retried when they are wanted.
    pending: u8,
}

impl<B1: I2c, B2: I2c> Tmp117Array<B1, B2> {
    /// The array over two buses with the thermometers of `fitted` (bit i =
    /// thermometer i) mounted; no bus traffic yet.
    pub fn new(bus1: B1, bus2: B2, fitted: u8) -> Self {
        Tmp117Array {
            bus1,
            bus2,
            fitted,
            pending: 0,
        }
    }

    /// Checks each fitted sensor's identity and starts its conversions.
    /// Those that fail are dropped from the fitted set (reads of them then
    /// fail); returns their mask (0: all answered).
    pub fn init(&mut self) -> u8 {
        let mut failed = 0u8;
        for i in 0..THERMOMETERS {
            let bit = 1u8 << i;
            if self.fitted & bit != 0 && self.with_sensor(i, |t| t.init().is_ok(), |t| t.init().is_ok()) != Some(true) {
                failed |= bit;
            }
        }
        self.fitted &= !failed;
        self.pending = failed;
        failed
    }

    /// The thermometers fitted and answering, as a bit mask.
    pub fn fitted(&self) -> u8 {
        self.fitted
    }

    /// Runs `on1` or `on2` on a driver for thermometer `i` on its bus.
    fn with_sensor<R>(
        &mut self,
        i: usize,
        on1: impl FnOnce(&mut Tmp117<&mut B1>) -> R,
        on2: impl FnOnce(&mut Tmp117<&mut B2>) -> R,
    ) -> Option<R> {
        let &address = ADDRESSES.get(i % PER_BUS)?;
        match i / PER_BUS {
            0 => Some(on1(&mut Tmp117::started(&mut self.bus1, address))),
            1 => Some(on2(&mut Tmp117::started(&mut self.bus2, address))),
            _ => None,
        }
    }

    /// Gives the buses back.
    pub fn destroy(self) -> (B1, B2) {
        (self.bus1, self.bus2)
    }
}

impl<B1: I2c, B2: I2c> crate::sensors::Thermometers for Tmp117Array<B1, B2> {
    fn read_wanted(&mut self, wanted: u8, readings: &mut Readings) -> u32 {
        let mut failed = 0;
        for (i, reading) in readings.iter_mut().enumerate() {
            let bit = 1u8 << i;
            *reading = None;
            if wanted & bit == 0 {
                continue;
            }
            // A mounted thermometer that has not answered yet: try its init again.
            if self.pending & bit != 0 && self.with_sensor(i, |t| t.init().is_ok(), |t| t.init().is_ok()) == Some(true)
            {
                self.pending &= !bit;
                self.fitted |= bit;
            }
            if self.fitted & bit != 0 {
                *reading = self
                    .with_sensor(i, |t| t.read_temp_c().ok(), |t| t.read_temp_c().ok())
                    .flatten();
            }
            failed += u32::from(reading.is_none());
        }
        failed
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
        let mut tmp = Tmp117::started(Mock::new(&expectations), 0x48);
        assert_eq!(tmp.read_temp_c(), Ok(25.0));
        assert_eq!(tmp.read_temp_c(), Ok(-0.007_812_5));
        assert_eq!(tmp.read_temp_c(), Err(SensorFault::Bus));
        tmp.destroy().done();
    }

    #[test]
    fn a_late_sensor_is_initialised_when_it_answers_and_its_power_on_value_is_no_reading() {
        let nack = ErrorKind::NoAcknowledge(embedded_hal::i2c::NoAcknowledgeSource::Address);
        let expectations = [
            Transaction::write_read(0x48, vec![REG_DEVICE_ID], vec![0, 0]).with_error(nack),
            Transaction::write_read(0x48, vec![REG_DEVICE_ID], vec![0x01, 0x17]),
            Transaction::write(0x48, vec![REG_CONFIGURATION, 0x00, 0x20]),
            Transaction::write_read(0x48, vec![REG_TEMP_RESULT], vec![0x80, 0x00]),
            Transaction::write_read(0x48, vec![REG_TEMP_RESULT], vec![0x0C, 0x80]),
        ];
        let mut tmp = Tmp117::new(Mock::new(&expectations), 0x48);
        assert_eq!(tmp.read_temp_c(), Err(SensorFault::NotReady), "not answering yet");
        assert_eq!(
            tmp.read_temp_c(),
            Err(SensorFault::NotReady),
            "−256 °C: not converted yet"
        );
        assert!(tmp.is_ready(), "not converted yet is no reset of its own");
        assert_eq!(tmp.read_temp_c(), Ok(25.0));
        tmp.destroy().done();
    }

    #[test]
    fn a_sensor_back_at_its_power_on_value_after_a_brown_out_is_initialised_again() {
        let expectations = [
            Transaction::write_read(0x48, vec![REG_TEMP_RESULT], vec![0x0C, 0x80]),
            // Its own brown-out: the result register at −256 °C, the
            // configuration back at the power-on one (a result a second).
            Transaction::write_read(0x48, vec![REG_TEMP_RESULT], vec![0x80, 0x00]),
            Transaction::write_read(0x48, vec![REG_DEVICE_ID], vec![0x01, 0x17]),
            Transaction::write(0x48, vec![REG_CONFIGURATION, 0x00, 0x20]),
            Transaction::write_read(0x48, vec![REG_TEMP_RESULT], vec![0x0C, 0x80]),
        ];
        let mut tmp = Tmp117::started(Mock::new(&expectations), 0x48);
        assert_eq!(tmp.read_temp_c(), Ok(25.0));
        assert_eq!(tmp.read_temp_c(), Err(SensorFault::NotReady));
        assert_eq!(tmp.read_temp_c(), Ok(25.0), "configured again, then read");
        tmp.destroy().done();
    }

    #[test]
    fn the_array_reads_only_wanted_sensors_each_on_its_bus_and_address() {
        use crate::sensors::Thermometers;
        let nack = ErrorKind::NoAcknowledge(embedded_hal::i2c::NoAcknowledgeSource::Address);
        // Fitted: temp_a, temp_c (bus 1) and temp_e, temp_h (bus 2); temp_h is
        // another device. Then a read of temp_a, temp_c − temp_e and temp_h.
        let id = |addr: u8| Transaction::write_read(addr, vec![REG_DEVICE_ID], vec![0x01, 0x17]);
        let start = |addr: u8| Transaction::write(addr, vec![REG_CONFIGURATION, 0x00, 0x20]);
        let bus1 = [
            id(0x48),
            start(0x48),
            id(0x4A),
            start(0x4A),
            Transaction::write_read(0x48, vec![REG_TEMP_RESULT], vec![0x0C, 0x80]),
            Transaction::write_read(0x4A, vec![REG_TEMP_RESULT], vec![0, 0]).with_error(nack),
        ];
        let bus2 = [
            id(0x48),
            start(0x48),
            Transaction::write_read(0x4B, vec![REG_DEVICE_ID], vec![0x02, 0x75]),
            Transaction::write_read(0x48, vec![REG_TEMP_RESULT], vec![0x0D, 0x00]),
            // temp_h's init is tried again when it is wanted.
            Transaction::write_read(0x4B, vec![REG_DEVICE_ID], vec![0x02, 0x75]),
        ];
        let mut array = Tmp117Array::new(Mock::new(&bus1), Mock::new(&bus2), 0b1001_0101);
        assert_eq!(array.init(), 0b1000_0000, "temp_h is not a TMP117");
        assert_eq!(array.fitted(), 0b0001_0101);
        let mut readings = [Some(99.0); THERMOMETERS];
        let failed = array.read_wanted(0b1001_0101, &mut readings);
        assert_eq!(readings, [Some(25.0), None, None, None, Some(26.0), None, None, None]);
        assert_eq!(failed, 2, "temp_c did not answer, temp_h is not there");
        let (mut b1, mut b2) = array.destroy();
        b1.done();
        b2.done();
    }
}
