//! QEMU replay board (netduinoplus2 = STM32F405): wiring only.
//!
//! Reads `input.csv` over semihosting from the directory QEMU runs in, takes
//! the model from flash slot MODEL_A (placed with `-device loader`), replays
//! the run through the real drivers on emulated buses ([`firmware_harness::replay`])
//! and writes `output.csv` (byte-identical to `trainer compensate`) and
//! `frames.bin` (the UART frames). A multi-axis run (`rate_x_dph` …) takes
//! a multi-axis blob (format 3, a model per axis or one shared basis for
//! every axis), decoded with the trainer's capacity
//! ([`rbf_core::MAX_CENTERS`] per axis: the replay checks the loop, not the
//! three-axis board's RAM), and goes through the multi-axis loop, one frame
//! per row with every axis. Run it with `cargo xtask qemu-replay`.
#![cfg_attr(target_os = "none", no_std, no_main)]

#[cfg(target_os = "none")]
mod board {
    #![allow(unsafe_code)]

    use core::cell::Cell;

    use cortex_m_rt::entry;
    use cortex_m_semihosting::{debug, hprintln};
    use firmware_harness::host_file::{HostFile, HostLines};
    use firmware_harness::replay::ReplayError;
    use firmware_harness::replay::{PeriodProbe, ReplaySample, Replayer};
    use rbf_core::blob::axes::{AxisModels, decode_axes_into};
    use rbf_core::blob::shared_layout::decode_shared_into;
    use rbf_core::blob::{BlobKind, blob_kind};
    use rbf_core::shared_basis::SharedAxisModels;

    /// Semihosting file as an embedded-io writer (the UART of the real board).
    struct HostWriter(HostFile);

    impl embedded_io::ErrorType for HostWriter {
        type Error = embedded_io::ErrorKind;
    }

    impl embedded_io::Write for HostWriter {
        fn write(&mut self, buf: &[u8]) -> Result<usize, Self::Error> {
            self.0
                .write_all(buf)
                .map(|()| buf.len())
                .map_err(|()| embedded_io::ErrorKind::Other)
        }
        fn flush(&mut self) -> Result<(), Self::Error> {
            Ok(())
        }
    }

    /// A line buffer flushed to a semihosting file.
    struct CsvOut {
        stream: HostFile,
        buf: heapless::String<2048>,
    }

    impl core::fmt::Write for CsvOut {
        fn write_str(&mut self, s: &str) -> core::fmt::Result {
            if self.buf.len() + s.len() > self.buf.capacity() {
                self.flush()?;
            }
            if s.len() > self.buf.capacity() {
                return self.stream.write_all(s.as_bytes()).map_err(|()| core::fmt::Error);
            }
            self.buf.push_str(s).map_err(|_| core::fmt::Error)
        }
    }

    impl CsvOut {
        fn flush(&mut self) -> core::fmt::Result {
            let r = self
                .stream
                .write_all(self.buf.as_bytes())
                .map_err(|()| core::fmt::Error);
            self.buf.clear();
            r
        }
    }

    /// Feeds every line of `lines` to `feed` (a replayer's `feed_line`, true
    /// when it took the line); a line that cannot be read or is refused ends the run.
    fn feed_lines(lines: &mut HostLines, mut feed: impl FnMut(&str) -> bool) {
        while let Some(line) = lines.next_line() {
            let Ok(line) = line else {
                fail("input.csv: a line is too long or not UTF-8")
            };
            if !feed(line) {
                fail("input.csv: malformed line or output refused");
            }
        }
    }

    fn fail(message: &str) -> ! {
        hprintln!("replay: {}", message);
        debug::exit(debug::EXIT_FAILURE);
        loop {
            cortex_m::asm::wfi();
        }
    }

    /// The axis models of a multi-axis replay (decoded in place, as the board does).
    static mut AXIS_MODELS: AxisModels<{ rbf_core::MAX_CENTERS }> = AxisModels::EMPTY;
    /// The shared-basis model of a multi-axis replay whose blob has one.
    static mut SHARED_MODELS: SharedAxisModels<{ rbf_core::MAX_CENTERS }> = SharedAxisModels::EMPTY;

    /// Replays every line through `replayer`; for a multi-axis run prints
    /// the per-axis thermometer faults; returns the loop's counters.
    fn replay<M: firmware::compensation::ModelHolder<{ rbf_core::MAX_CENTERS }, N>, const N: usize>(
        lines: &mut HostLines,
        out: &mut CsvOut,
        replayer: Result<Replayer<'_, HostWriter, M, { rbf_core::MAX_CENTERS }, N>, ReplayError>,
    ) -> firmware::compensation::LoopStats {
        let Ok(mut replayer) = replayer else {
            fail("emulated devices did not initialise")
        };
        feed_lines(lines, |line| replayer.feed_line(line, out).is_ok());
        if let &[x, y, z] = replayer.temp_read_faults_per_axis().as_slice() {
            hprintln!("replay: temp_read_faults per axis x {} y {} z {}", x, y, z);
        }
        replayer.stats()
    }

    #[entry]
    fn main() -> ! {
        firmware::board::paint_stack();

        // Pass 1: nominal period by the shared rule, and whether the run has axes.
        let (period_s, multi_axis) = {
            let Some(mut lines) = HostLines::open("input.csv\0") else {
                fail("cannot open input.csv")
            };
            let mut probe = PeriodProbe::default();
            while let Some(line) = lines.next_line() {
                match line.map(|l| probe.feed_line(l)) {
                    Ok(Ok(false)) => {}
                    Ok(Ok(true)) => break,
                    _ => fail("input.csv: unreadable header or row"),
                }
            }
            (probe.period_s(), probe.is_multi_axis())
        };

        // Pass 2: replay through the drivers and the loop.
        let Some(mut lines) = HostLines::open("input.csv\0") else {
            fail("cannot reopen input.csv")
        };
        let Some(output) = HostFile::create("output.csv\0") else {
            fail("cannot create output.csv")
        };
        let Some(frames) = HostFile::create("frames.bin\0") else {
            fail("cannot create frames.bin")
        };
        let mut out = CsvOut {
            stream: output,
            buf: heapless::String::new(),
        };
        let slot = firmware::board::model_slot_a();
        let current: [Cell<ReplaySample>; 3] = Default::default();
        let stats = if multi_axis && blob_kind(slot) == Ok(BlobKind::SharedBasis) {
            // SAFETY: the only reference to SHARED_MODELS, taken once in main.
            let models = unsafe { &mut *core::ptr::addr_of_mut!(SHARED_MODELS) };
            let models = match decode_shared_into(models, slot) {
                Ok(_) => {
                    hprintln!("replay: shared-basis model");
                    Some(&*models)
                }
                Err(e) => {
                    hprintln!("replay: model slot refused ({}); output uncompensated with flag 4", e);
                    None
                }
            };
            let replayer = Replayer::new(models, period_s, &current, HostWriter(frames));
            replay(&mut lines, &mut out, replayer)
        } else if multi_axis {
            // SAFETY: the only reference to AXIS_MODELS, taken once in main.
            let models = unsafe { &mut *core::ptr::addr_of_mut!(AXIS_MODELS) };
            let models = match decode_axes_into(models, slot) {
                Ok(_) => Some(&*models),
                Err(e) => {
                    hprintln!("replay: model slot refused ({}); output uncompensated with flag 4", e);
                    None
                }
            };
            let replayer = Replayer::new(models, period_s, &current, HostWriter(frames));
            replay(&mut lines, &mut out, replayer)
        } else {
            let model = firmware::load_model(slot);
            if let Err(e) = &model {
                hprintln!("replay: model slot refused ({}); output uncompensated with flag 4", e);
            }
            let model = model.ok();
            let current: [Cell<ReplaySample>; 1] = Default::default();
            let replayer = Replayer::new(model.as_ref(), period_s, &current, HostWriter(frames));
            replay(&mut lines, &mut out, replayer)
        };
        if out.flush().is_err() {
            fail("cannot write output.csv");
        }
        hprintln!(
            "replay: samples {} temp_read_faults {} rate_read_faults {} output_errors {} stack_peak_bytes {}",
            stats.samples,
            stats.temp_read_faults,
            stats.rate_read_faults,
            stats.output_errors,
            firmware::board::stack_peak_bytes()
        );
        debug::exit(debug::EXIT_SUCCESS);
        loop {
            cortex_m::asm::wfi();
        }
    }
}

#[cfg(not(target_os = "none"))]
fn main() {
    eprintln!("qemu-replay runs under qemu-system-arm: use `cargo xtask qemu-replay`");
}
