//! Driver for the IFOG rate front end on SPI (protocol: docs/frontend.md).
//!
//! Each access is one SPI transaction: a command byte `0x80 | register`, then
//! the register's bytes clocked out big-endian. The SAMPLE register carries a
//! status word, the rate as IEEE-754 binary32 and a CRC-8 over both.

use embedded_hal::spi::{Operation, SpiDevice};

use crate::sensors::{RateFrontEnd, RateSample, SensorFault};

/// Identity register (u16).
pub const REG_WHO_AM_I: u8 = 0x00;
/// Scale factor register (binary32, °/h per front-end unit).
pub const REG_SCALE_FACTOR: u8 = 0x01;
/// Sample register: STATUS (u16) · RATE (binary32) · CRC-8.
pub const REG_SAMPLE: u8 = 0x10;
/// Read command bit.
pub const READ: u8 = 0x80;
/// What WHO_AM_I reads.
pub const WHO_AM_I: u16 = 0xF06A;
/// Bytes of the SAMPLE register.
pub const SAMPLE_LEN: usize = 7;
/// STATUS: the rate word is a measurement.
pub const STATUS_VALID: u16 = 1 << 0;
/// STATUS: the rate exceeded the measurement range.
pub const STATUS_OVER_RANGE: u16 = 1 << 1;
/// STATUS: the closed loop lost lock.
pub const STATUS_LOOP_UNLOCKED: u16 = 1 << 2;
/// STATUS bits 8–15: the front end's sample counter (one step per sample).
pub const STATUS_COUNTER_SHIFT: u32 = 8;
/// Consecutive failed sample reads after which the front end is taken for
/// reset and initialised afresh (its scale factor read again).
pub const REINIT_AFTER_FAULTS: u8 = 16;

const CRC8: crc::Crc<u8> = crc::Crc::<u8>::new(&crc::CRC_8_SMBUS);

/// The SAMPLE register bytes for a status word and rate word (the front end's side).
pub fn encode_sample(status: u16, rate_word: f32) -> [u8; SAMPLE_LEN] {
    let mut b = [0u8; SAMPLE_LEN];
    b[0..2].copy_from_slice(&status.to_be_bytes());
    b[2..6].copy_from_slice(&rate_word.to_bits().to_be_bytes());
    b[6] = CRC8.checksum(&b[0..6]);
    b
}

/// The SPI clock to ask for at a peripheral clock of `pclk_hz` so that the
/// front end sees at most `max_hz`: `pclk_hz / d`, with `d` the smallest
/// of the STM32 SPI dividers (2, 4, … 256) that keeps within `max_hz`. A
/// request of exactly `pclk_hz / d` is one the stm32f4xx-hal rounds to `d`
/// itself (its table maps 6 … 11 to ÷8, so 84 MHz / 8 MHz would give
/// 10.5 MHz); a clock too fast for ÷256 gives `pclk_hz / 256`.
pub const fn spi_clock_hz(pclk_hz: u32, max_hz: u32) -> u32 {
    pclk_hz / spi_divider(pclk_hz, max_hz)
}

/// The smallest STM32 SPI divider (2, 4, … 256) that keeps `pclk_hz` within `max_hz`.
pub const fn spi_divider(pclk_hz: u32, max_hz: u32) -> u32 {
    let mut divider = 2;
    while divider < 256 && pclk_hz / divider > max_hz {
        divider *= 2;
    }
    divider
}

/// Driver errors.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Error<E> {
    /// SPI transaction failed.
    Spi(E),
    /// WHO_AM_I read this instead of 0xF06A.
    WrongDevice(u16),
    /// The scale factor is not a positive finite number.
    BadScaleFactor,
    /// A sample failed its CRC.
    Crc,
    /// The front end has not answered [`FrontEnd::init`] yet: no scale factor.
    NotReady,
    /// SAMPLE's counter has not moved since the last read: no new sample.
    Stale,
}

/// The front end on an SPI device it owns.
///
/// There is no default scale factor: until the front end has answered
/// [`FrontEnd::init`] every read fails ([`Error::NotReady`]; through
/// [`RateFrontEnd::read_rate`], which retries the init on each sample, a
/// flagged frame). [`REINIT_AFTER_FAULTS`] failed reads in a row (a front
/// end that reset or lost power) make it initialise afresh.
#[derive(Debug)]
pub struct FrontEnd<SPI> {
    spi: SPI,
    /// °/h per rate unit, once the front end answered.
    scale_dph: Option<f32>,
    /// STATUS's sample counter of the last sample read.
    last_counter: Option<u8>,
    /// Failed reads since the last good one.
    faults_in_row: u8,
    /// Times the front end was (re)initialised successfully.
    inits: u32,
}

impl<SPI: SpiDevice> FrontEnd<SPI> {
    /// A driver without a scale factor (not ready) until [`FrontEnd::init`] reads one.
    pub fn new(spi: SPI) -> Self {
        FrontEnd {
            spi,
            scale_dph: None,
            last_counter: None,
            faults_in_row: 0,
            inits: 0,
        }
    }

    /// Whether the front end answered its init (a scale factor is known).
    pub fn is_ready(&self) -> bool {
        self.scale_dph.is_some()
    }

    /// Successful initialisations so far (more than one: the front end was re-initialised).
    pub fn inits(&self) -> u32 {
        self.inits
    }

    fn read<const N: usize>(&mut self, register: u8) -> Result<[u8; N], Error<SPI::Error>> {
        let mut buf = [0u8; N];
        self.spi
            .transaction(&mut [Operation::Write(&[READ | register]), Operation::Read(&mut buf)])
            .map_err(Error::Spi)?;
        Ok(buf)
    }

    /// Checks identity and reads the scale factor.
    #[inline(never)]
    pub fn init(&mut self) -> Result<(), Error<SPI::Error>> {
        let id = u16::from_be_bytes(self.read::<2>(REG_WHO_AM_I)?);
        if id != WHO_AM_I {
            return Err(Error::WrongDevice(id));
        }
        let scale = f32::from_bits(u32::from_be_bytes(self.read::<4>(REG_SCALE_FACTOR)?));
        if !(scale.is_finite() && scale > 0.0) {
            return Err(Error::BadScaleFactor);
        }
        self.scale_dph = Some(scale);
        self.last_counter = None;
        self.faults_in_row = 0;
        self.inits = self.inits.wrapping_add(1);
        Ok(())
    }

    /// Reads the current sample: rate in °/h and whether the front end
    /// vouches for it. A sample whose counter (STATUS bits 8–15) equals the
    /// last one read is no new sample ([`Error::Stale`]): a glitch on
    /// data-ready, or a read before the front end had converted.
    pub fn read_sample(&mut self) -> Result<RateSample, Error<SPI::Error>> {
        let scale_dph = self.scale_dph.ok_or(Error::NotReady)?;
        let b = self.read::<SAMPLE_LEN>(REG_SAMPLE)?;
        if CRC8.checksum(&b[0..6]) != b[6] {
            return Err(Error::Crc);
        }
        let status = u16::from_be_bytes([b[0], b[1]]);
        let counter = (status >> STATUS_COUNTER_SHIFT) as u8;
        if self.last_counter.replace(counter) == Some(counter) {
            return Err(Error::Stale);
        }
        let word = f32::from_bits(u32::from_be_bytes([b[2], b[3], b[4], b[5]]));
        let valid = status & STATUS_VALID != 0 && status & (STATUS_OVER_RANGE | STATUS_LOOP_UNLOCKED) == 0;
        Ok(RateSample {
            rate_dph: word * scale_dph,
            valid,
        })
    }

    /// Gives the SPI device back.
    pub fn destroy(self) -> SPI {
        self.spi
    }
}

/// The SAMPLE register bytes of the front end's sample number `counter`
/// (STATUS bits 8–15; the front end's side, emulations and tests).
pub fn encode_counted_sample(status: u16, counter: u8, rate_word: f32) -> [u8; SAMPLE_LEN] {
    encode_sample(status | (u16::from(counter) << STATUS_COUNTER_SHIFT), rate_word)
}

impl<SPI: SpiDevice> RateFrontEnd for FrontEnd<SPI> {
    /// Initialises the front end first while it has not answered (one try
    /// per sample: a front end that boots after the MCU is picked up as
    /// soon as it answers), then reads the sample.
    fn read_rate(&mut self) -> Result<RateSample, SensorFault> {
        if self.faults_in_row >= REINIT_AFTER_FAULTS {
            self.scale_dph = None;
        }
        if self.scale_dph.is_none() && self.init().is_err() {
            return Err(SensorFault::NotReady);
        }
        let read = self.read_sample();
        self.faults_in_row = match read {
            Ok(_) => 0,
            Err(_) => self.faults_in_row.saturating_add(1),
        };
        read.map_err(|e| match e {
            Error::Crc => SensorFault::Integrity,
            Error::WrongDevice(_) | Error::BadScaleFactor | Error::NotReady => SensorFault::NotReady,
            Error::Stale => SensorFault::Stale,
            Error::Spi(_) => SensorFault::Bus,
        })
    }
}

#[cfg(test)]
#[allow(clippy::float_cmp, reason = "binary32 words pass through exactly")]
mod tests {
    use super::*;
    use embedded_hal::spi::ErrorKind;
    use embedded_hal_mock::eh1::spi::{Mock, Transaction};

    fn read(register: u8, reply: &[u8]) -> Vec<Transaction<u8>> {
        vec![
            Transaction::transaction_start(),
            Transaction::write(READ | register),
            Transaction::read_vec(reply.to_vec()),
            Transaction::transaction_end(),
        ]
    }

    #[test]
    fn init_reads_identity_and_scale_then_samples_scale_the_rate_word() {
        let mut script = read(REG_WHO_AM_I, &[0xF0, 0x6A]);
        script.extend(read(REG_SCALE_FACTOR, &2.0f32.to_bits().to_be_bytes()));
        script.extend(read(REG_SAMPLE, &encode_counted_sample(STATUS_VALID, 1, 10.25)));
        script.extend(read(
            REG_SAMPLE,
            &encode_counted_sample(STATUS_VALID | STATUS_OVER_RANGE, 2, 1e7),
        ));
        let mut fe = FrontEnd::new(Mock::new(&script));
        fe.init().unwrap();
        assert_eq!(
            fe.read_rate(),
            Ok(RateSample {
                rate_dph: 20.5,
                valid: true
            })
        );
        assert_eq!(
            fe.read_rate(),
            Ok(RateSample {
                rate_dph: 2e7,
                valid: false
            })
        );
        fe.destroy().done();
    }

    #[test]
    fn wrong_identity_and_bad_scale_are_refused() {
        let mut fe = FrontEnd::new(Mock::new(&read(REG_WHO_AM_I, &[0x12, 0x34])));
        assert_eq!(fe.init(), Err(Error::WrongDevice(0x1234)));
        fe.destroy().done();
        let mut script = read(REG_WHO_AM_I, &[0xF0, 0x6A]);
        script.extend(read(REG_SCALE_FACTOR, &f32::NAN.to_bits().to_be_bytes()));
        let mut fe = FrontEnd::new(Mock::new(&script));
        assert_eq!(fe.init(), Err(Error::BadScaleFactor));
        fe.destroy().done();
    }

    /// An SPI device whose every transaction fails (embedded-hal-mock's SPI
    /// mock cannot inject errors).
    struct FailingSpi;

    impl embedded_hal::spi::ErrorType for FailingSpi {
        type Error = ErrorKind;
    }

    impl SpiDevice for FailingSpi {
        fn transaction(&mut self, _: &mut [Operation<'_, u8>]) -> Result<(), ErrorKind> {
            Err(ErrorKind::Overrun)
        }
    }

    #[test]
    fn the_spi_clock_stays_within_the_front_ends_10_mhz_through_the_hals_rounding() {
        // stm32f4xx-hal 0.23 (spi.rs): the divider code from pclk / request.
        let hal_divider = |pclk: u32, request: u32| match pclk / request {
            0..=2 => 2,
            3..=5 => 4,
            6..=11 => 8,
            12..=23 => 16,
            24..=47 => 32,
            48..=95 => 64,
            96..=191 => 128,
            _ => 256,
        };
        assert_eq!(spi_clock_hz(84_000_000, 10_000_000), 5_250_000);
        assert_eq!(hal_divider(84_000_000, 8_000_000), 8, "the old request: 10.5 MHz");
        for pclk in [16_000_000, 42_000_000, 84_000_000, 90_000_000] {
            let request = spi_clock_hz(pclk, 10_000_000);
            let actual = pclk / hal_divider(pclk, request);
            assert!(actual <= 10_000_000 && actual == request, "{pclk}: {actual}");
        }
    }

    fn init_script(scale: f32) -> Vec<Transaction<u8>> {
        let mut script = read(REG_WHO_AM_I, &[0xF0, 0x6A]);
        script.extend(read(REG_SCALE_FACTOR, &scale.to_bits().to_be_bytes()));
        script
    }

    #[test]
    fn corrupted_samples_and_bus_errors_are_faults() {
        let mut corrupted = encode_sample(STATUS_VALID, 1.0);
        corrupted[3] ^= 0x01;
        let mut script = init_script(1.0);
        script.extend(read(REG_SAMPLE, &corrupted));
        let mut fe = FrontEnd::new(Mock::new(&script));
        assert_eq!(fe.read_rate(), Err(SensorFault::Integrity));
        fe.destroy().done();
        assert_eq!(FrontEnd::new(FailingSpi).read_rate(), Err(SensorFault::NotReady));
    }

    #[test]
    fn a_front_end_that_boots_late_gives_no_rate_until_it_answers_then_its_own_scale() {
        // First sample: WHO_AM_I reads 0xFFFF (electronics not up): no
        // SAMPLE read at all, never a rate at scale 1. Second: it answers.
        let mut script = read(REG_WHO_AM_I, &[0xFF, 0xFF]);
        script.extend(init_script(4.0));
        script.extend(read(REG_SAMPLE, &encode_counted_sample(STATUS_VALID, 7, 2.5)));
        let mut fe = FrontEnd::new(Mock::new(&script));
        assert_eq!(fe.read_rate(), Err(SensorFault::NotReady));
        assert!(!fe.is_ready());
        assert_eq!(fe.read_rate().map(|s| s.rate_dph), Ok(10.0));
        assert_eq!(fe.inits(), 1);
        fe.destroy().done();
    }

    #[test]
    fn a_sample_whose_counter_did_not_move_is_stale_not_a_new_sample() {
        let mut script = init_script(1.0);
        script.extend(read(REG_SAMPLE, &encode_counted_sample(STATUS_VALID, 255, 1.0)));
        script.extend(read(REG_SAMPLE, &encode_counted_sample(STATUS_VALID, 255, 1.0)));
        script.extend(read(REG_SAMPLE, &encode_counted_sample(STATUS_VALID, 0, 3.0)));
        let mut fe = FrontEnd::new(Mock::new(&script));
        assert!(fe.read_rate().is_ok());
        assert_eq!(fe.read_rate(), Err(SensorFault::Stale));
        assert_eq!(fe.read_rate().map(|s| s.rate_dph), Ok(3.0), "the counter wraps");
        fe.destroy().done();
    }
}
