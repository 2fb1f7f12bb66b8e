//! The compensation loop against embedded-hal-mock transaction scripts: a
//! recorded run becomes the exact I2C and SPI traffic the drivers must
//! produce, and the loop's numbers equal `trainer compensate`'s bit for bit.

use e2e_tests::fixtures as common;

use embedded_hal::i2c::{ErrorKind, NoAcknowledgeSource};
use embedded_hal_mock::eh1::i2c::{Mock as I2cMock, Transaction as I2cTransaction};
use embedded_hal_mock::eh1::spi::{Mock as SpiMock, Transaction as SpiTransaction};
use firmware::compensation::{CompensationLoop, LoopConfig};
use firmware::frontend::{self, FrontEnd};
use firmware::tmp117::{self, Tmp117};
use gyro_wire::frame::{self, OutputFrame};
use rbf_core::sensor::tmp117_raw;
use rbf_core::{CompensatorConfig, Flags, Model};
use trainer::evaluation::evaluate::compensate_run;
use trainer::reading::run::samples::Run;

const ADDRESS: u8 = tmp117::DEFAULT_ADDRESS;

fn spi_read(register: u8, reply: Vec<u8>) -> [SpiTransaction<u8>; 4] {
    [
        SpiTransaction::transaction_start(),
        SpiTransaction::write(frontend::READ | register),
        SpiTransaction::read_vec(reply),
        SpiTransaction::transaction_end(),
    ]
}

/// The front end's init traffic (identity, scale factor 1), which the
/// driver sends before its first sample read.
fn spi_init() -> Vec<SpiTransaction<u8>> {
    let mut script = spi_read(frontend::REG_WHO_AM_I, frontend::WHO_AM_I.to_be_bytes().to_vec()).to_vec();
    script.extend(spi_read(
        frontend::REG_SCALE_FACTOR,
        1.0f32.to_bits().to_be_bytes().to_vec(),
    ));
    script
}

/// The TMP117's init traffic (identity, continuous conversion), which the
/// driver sends before its first temperature read.
fn i2c_init() -> Vec<I2cTransaction> {
    vec![
        I2cTransaction::write_read(ADDRESS, vec![tmp117::REG_DEVICE_ID], vec![0x01, 0x17]),
        I2cTransaction::write(ADDRESS, vec![tmp117::REG_CONFIGURATION, 0x00, 0x20]),
    ]
}

#[test]
fn recorded_run_through_the_mock_hal_gives_the_trainers_numbers() {
    let dir = tempfile::TempDir::new().unwrap();
    let (model, slice) = common::model_and_faulty_slice(dir.path());
    let run = Run::load(&slice).unwrap();
    let expected = compensate_run(Some(&model), &run);

    let mut i2c_script = i2c_init();
    let mut spi_script = spi_init();
    for i in 0..run.len() {
        let temp = I2cTransaction::write_read(ADDRESS, vec![tmp117::REG_TEMP_RESULT], vec![0, 0]);
        i2c_script.push(match run.temp_c[i] {
            Some(t) => I2cTransaction::write_read(
                ADDRESS,
                vec![tmp117::REG_TEMP_RESULT],
                tmp117_raw(t).to_be_bytes().to_vec(),
            ),
            None => temp.with_error(ErrorKind::NoAcknowledge(NoAcknowledgeSource::Address)),
        });
        let word = frontend::encode_counted_sample(frontend::STATUS_VALID, i as u8, run.rate_dph[i] as f32);
        spi_script.extend(spi_read(frontend::REG_SAMPLE, word.to_vec()));
    }
    let config = LoopConfig {
        compensator: CompensatorConfig::for_nominal_period_s(run.nominal_period_s),
        temp_read_every: 1,
    };
    let mut frames = Vec::new();
    let mut lp = CompensationLoop::new(
        Some(model.clone()),
        config,
        Tmp117::new(I2cMock::new(&i2c_script), ADDRESS),
        FrontEnd::new(SpiMock::new(&spi_script)),
        &mut frames,
    );
    for (i, sample) in run.samples().enumerate() {
        let [out] = lp.step(sample.dt_s);
        assert_eq!(out.bias_dph.to_bits(), expected[i].bias_dph.to_bits(), "row {i}");
        assert_eq!(
            out.rate_comp_dph.to_bits(),
            expected[i].rate_comp_dph.to_bits(),
            "row {i}"
        );
        assert_eq!(out.flags, expected[i].flags, "row {i}");
        assert_eq!(
            out.flags.contains(Flags::TEMP_SENSOR_FAULT),
            common::faulty(i),
            "row {i}"
        );
    }
    assert_eq!(lp.stats().temp_read_faults, common::FAULTY_ROWS);
    let (t, f, _) = lp.destroy();
    t.destroy().done();
    f.destroy().done();
    let count = frames.split(|&b| b == 0).filter(|c| !c.is_empty()).count();
    assert_eq!(count, run.len(), "one frame per sample");
}

#[test]
fn decimated_temperature_reads_and_front_end_faults_still_emit_every_frame() {
    // Thermometer read every 4th sample; the front end sends a corrupt sample
    // (CRC), an over-range one and a NaN word: all flagged 16, none dropped.
    let mut i2c_script = i2c_init();
    let mut spi_script = spi_init();
    let words: [(u16, f32, bool); 8] = [
        (frontend::STATUS_VALID, 10.0, true),
        (frontend::STATUS_VALID, 11.0, true),
        (frontend::STATUS_VALID, 12.0, false), // corrupted on the wire
        (frontend::STATUS_VALID | frontend::STATUS_OVER_RANGE, 4e6, true),
        (frontend::STATUS_VALID, f32::NAN, true),
        (frontend::STATUS_VALID | frontend::STATUS_LOOP_UNLOCKED, 13.0, true),
        (frontend::STATUS_VALID, 14.0, true),
        (0, 15.0, true), // not VALID
    ];
    for (i, &(status, word, crc_ok)) in words.iter().enumerate() {
        if i % 4 == 0 {
            i2c_script.push(I2cTransaction::write_read(
                ADDRESS,
                vec![tmp117::REG_TEMP_RESULT],
                vec![0x0C, 0x80],
            ));
        }
        let mut bytes = frontend::encode_counted_sample(status, i as u8, word).to_vec();
        if !crc_ok {
            bytes[6] ^= 0xFF;
        }
        spi_script.extend(spi_read(frontend::REG_SAMPLE, bytes));
    }
    let config = LoopConfig {
        compensator: CompensatorConfig::for_sample_rate(1.0),
        temp_read_every: 4,
    };
    let mut frames = Vec::new();
    let mut lp = CompensationLoop::new(
        None::<Model>,
        config,
        Tmp117::new(I2cMock::new(&i2c_script), ADDRESS),
        FrontEnd::new(SpiMock::new(&spi_script)),
        &mut frames,
    );
    let flags: Vec<Flags> = (0..words.len()).map(|_| lp.step(1.0)[0].flags).collect();
    let invalid: Vec<bool> = flags.iter().map(|f| f.contains(Flags::RATE_INVALID)).collect();
    assert_eq!(invalid, [false, false, true, true, true, true, false, true]);
    assert!(
        flags.iter().all(|f| f.contains(Flags::NO_VALID_MODEL)),
        "no model: flag 4 on every frame"
    );
    assert!(
        flags.iter().all(|f| !f.contains(Flags::TEMP_SENSOR_FAULT)),
        "held reading between reads is not a fault"
    );
    assert_eq!(lp.stats().rate_read_faults, 1);
    let (t, f, _) = lp.destroy();
    t.destroy().done();
    f.destroy().done();
    let mut decoded: Vec<_> = frames
        .split_mut(|&b| b == 0)
        .filter(|c| !c.is_empty())
        .map(|c| frame::decode(c).unwrap())
        .collect();
    assert_eq!(decoded.len(), words.len());
    assert!(
        decoded[2].rate_dph.is_nan(),
        "a failed SPI read is reported as NaN rate"
    );
    assert_eq!(decoded.pop().unwrap().seq, 7);
}

/// An output that refuses every write: the loop counts it and goes on.
struct BrokenUart;

impl embedded_io::ErrorType for BrokenUart {
    type Error = embedded_io::ErrorKind;
}

impl embedded_io::Write for BrokenUart {
    fn write(&mut self, _: &[u8]) -> Result<usize, Self::Error> {
        Err(embedded_io::ErrorKind::Other)
    }
    fn flush(&mut self) -> Result<(), Self::Error> {
        Ok(())
    }
}

/// A loop without a model at 1 Hz over `samples` valid front-end samples
/// and one thermometer read, writing to `output`.
fn loop_over<W: embedded_io::Write>(
    samples: usize,
    output: W,
) -> CompensationLoop<Tmp117<I2cMock>, FrontEnd<SpiMock<u8>>, W> {
    let mut i2c = i2c_init();
    i2c.push(I2cTransaction::write_read(
        ADDRESS,
        vec![tmp117::REG_TEMP_RESULT],
        vec![0x0C, 0x80],
    ));
    let mut spi = spi_init();
    spi.extend((0..samples).flat_map(|i| {
        spi_read(
            frontend::REG_SAMPLE,
            frontend::encode_counted_sample(frontend::STATUS_VALID, i as u8, 1.0).to_vec(),
        )
    }));
    let config = LoopConfig {
        compensator: CompensatorConfig::for_sample_rate(1.0),
        temp_read_every: 100,
    };
    CompensationLoop::new(
        None,
        config,
        Tmp117::new(I2cMock::new(&i2c), ADDRESS),
        FrontEnd::new(SpiMock::new(&spi)),
        output,
    )
}

#[test]
fn a_failing_output_is_counted_and_never_stops_the_loop() {
    let mut lp = loop_over(3, BrokenUart);
    for _ in 0..3 {
        lp.step(1.0);
    }
    assert_eq!(lp.stats().output_errors, 3);
    assert_eq!(lp.stats().samples, 3);
    let (t, f, _) = lp.destroy();
    t.destroy().done();
    f.destroy().done();
}

/// A UART like the stm32f4xx-hal one while its data register is full: it
/// takes nothing (`Ok(0)`) for the first `busy` writes, then everything.
struct StallingUart {
    busy: u32,
    taken: Vec<u8>,
}

impl embedded_io::ErrorType for StallingUart {
    type Error = embedded_io::ErrorKind;
}

impl embedded_io::Write for StallingUart {
    fn write(&mut self, buf: &[u8]) -> Result<usize, Self::Error> {
        if self.busy > 0 {
            self.busy -= 1;
            return Ok(0);
        }
        self.taken.extend_from_slice(buf);
        Ok(buf.len())
    }
    fn flush(&mut self) -> Result<(), Self::Error> {
        Ok(())
    }
}

#[test]
fn an_output_that_takes_nothing_drops_the_frame_and_flags_the_next_one_without_panicking() {
    let mut lp = loop_over(
        4,
        StallingUart {
            busy: 2,
            taken: Vec::new(),
        },
    );
    // Edge 0, 1, 2 refused/sent as the UART allows; edge 3 then 6 (4 and 5
    // passed while the CPU was stalled).
    lp.step_at(0, 1.0);
    lp.step_at(1, 1.0);
    lp.step_at(2, 1.0);
    lp.step_at(5, 3.0);
    assert_eq!(lp.stats().output_errors, 2);
    assert_eq!(lp.stats().samples_missed, 2);
    let (t, f, uart) = lp.destroy();
    t.destroy().done();
    f.destroy().done();
    let frames: Vec<OutputFrame> = uart
        .taken
        .split(|b| *b == 0)
        .filter(|f| !f.is_empty())
        .map(|f| {
            let mut f = f.to_vec();
            f.push(0);
            gyro_wire::frame::decode(&mut f).unwrap()
        })
        .collect();
    assert_eq!(frames.len(), 2, "two frames sent, two dropped");
    assert_eq!(frames[0].seq, 2);
    assert!(Flags(frames[0].flags).contains(Flags::OUTPUT_DROPPED));
    assert_eq!(frames[1].seq, 5, "the sequence number counts data-ready edges");
    assert!(Flags(frames[1].flags).contains(Flags::SAMPLES_MISSED));
    assert!(!Flags(frames[1].flags).contains(Flags::OUTPUT_DROPPED));
}
