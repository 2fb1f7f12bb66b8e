//! QEMU fault board (netduinoplus2 = STM32F405): the fault-injection
//! campaigns of [`firmware_harness::fault_injection`] on the target.
//!
//! The model to run comes from flash slot MODEL_A, the update to install from
//! MODEL_B (both placed with `-device loader`). QEMU's flash is read-only and
//! its flash controller is not modelled, so the power-safe update runs on
//! [`firmware_harness::emulated_flash`] in RAM with the same store code the real
//! board uses. Prints one line per campaign and ends with
//! `faults injected N, samples lost 0, panics 0`; exits with failure if any
//! criterion fails. Run it with `cargo xtask qemu-faults`.
#![cfg_attr(target_os = "none", no_std, no_main)]

#[cfg(target_os = "none")]
mod board {
    use cortex_m_rt::entry;
    use cortex_m_semihosting::{debug, hprintln};
    use firmware_harness::fault_injection::{
        axis_thermometer_campaign, bit_flip_campaign, command_campaign, power_cut_campaign, sensor_campaign,
    };
    use rbf_core::axis::Axis;
    use rbf_core::blob::axes::{AxisModels, decode_axes_into, encode_axes};
    use rbf_core::blob::{self, Header, MAX_BLOB_LEN};

    /// A three-axis IMU's models: x and z the running model, y the update
    /// (built into a multi-axis blob, decoded with the board's capacity).
    static mut ALL_AXES: AxisModels = AxisModels::EMPTY;
    static mut BOARD_AXES: AxisModels<{ firmware::AXIS_CENTERS }> = AxisModels::EMPTY;
    static mut AXES_BLOB: [u8; MAX_BLOB_LEN] = [0; MAX_BLOB_LEN];

    #[allow(unsafe_code)]
    fn board_axes(old: &[u8], new: &[u8]) -> Option<&'static AxisModels<{ firmware::AXIS_CENTERS }>> {
        // SAFETY: the only references to these statics, taken once in main.
        let (all, board, buf) = unsafe {
            (
                &mut *core::ptr::addr_of_mut!(ALL_AXES),
                &mut *core::ptr::addr_of_mut!(BOARD_AXES),
                &mut *core::ptr::addr_of_mut!(AXES_BLOB),
            )
        };
        let (old, new) = (blob::decode(old).ok()?.model, blob::decode(new).ok()?.model);
        all.insert(Axis::X, old.clone());
        all.insert(Axis::Y, new);
        all.insert(Axis::Z, old);
        let n = encode_axes(all, buf).ok()?;
        decode_axes_into(board, buf.get(..n)?).ok()?;
        Some(board)
    }

    /// Gyro samples of the sensor-fault campaign.
    const SAMPLES: u32 = 20_000;
    /// Seed of its fault schedule.
    const SEED: u32 = 0x1234_5678;

    /// The blob at the start of a slot, if the header describes one that fits.
    fn blob_in(slot: &'static [u8]) -> Option<&'static [u8]> {
        let len = Header::parse(slot).ok()?.blob_len();
        slot.get(..len)
    }

    fn finish(ok: bool) -> ! {
        debug::exit(if ok { debug::EXIT_SUCCESS } else { debug::EXIT_FAILURE });
        loop {
            cortex_m::asm::wfi();
        }
    }

    #[entry]
    fn main() -> ! {
        firmware::board::paint_stack();
        let (Some(old), Some(new)) = (
            blob_in(firmware::board::model_slot_a()),
            blob_in(firmware::board::model_slot_b()),
        ) else {
            hprintln!("faults: MODEL_A and MODEL_B must each hold a blob");
            finish(false)
        };
        let model = blob::decode(old).ok().map(|d| d.model);

        let sensors = sensor_campaign(model, SAMPLES, SEED);
        hprintln!(
            "faults: sensors: samples {} frames {} episodes nack {} stuck {} rail {} spike {} out-of-range {} spi {} nan {} crc {} faulty-samples {} missing-flags {} non-finite {}",
            sensors.samples,
            sensors.frames,
            sensors.episodes[0],
            sensors.episodes[1],
            sensors.episodes[2],
            sensors.episodes[3],
            sensors.episodes[4],
            sensors.episodes[5],
            sensors.episodes[6],
            sensors.episodes[7],
            sensors.faulty_samples,
            sensors.missing_flags,
            sensors.non_finite
        );
        let (flips_old, accepted_old) = bit_flip_campaign(old);
        let (flips_new, accepted_new) = bit_flip_campaign(new);
        hprintln!(
            "faults: model region: bit flips {} accepted {}",
            flips_old + flips_new,
            accepted_old + accepted_new
        );
        let update = power_cut_campaign(old, new);
        hprintln!(
            "faults: update: flash operations per install {} resets {} booted old {} booted new {} booted invalid {} retry failures {}",
            update.operations_per_install,
            update.resets,
            update.booted_old,
            update.booted_new,
            update.booted_invalid,
            update.retry_failures
        );
        let commands = command_campaign(old, new);
        hprintln!(
            "faults: uart commands {} expected replies {} switched {}",
            commands.commands,
            commands.expected_replies,
            commands.switched
        );
        let Some(axes_models) = board_axes(old, new) else {
            hprintln!("faults: the slots' models do not make a three-axis blob the board holds");
            finish(false)
        };
        let axes = axis_thermometer_campaign(Some(axes_models), Axis::Y, SAMPLES, SEED);
        let [tx, ty, tz] = axes.temp_read_faults_per_axis;
        hprintln!(
            "faults: axes: y thermometer failing: samples {} frames {} faulty-samples {} missing-flags {} y-uncompensated {} others-disturbed {} temp-read-faults x {} y {} z {}",
            axes.samples,
            axes.frames,
            axes.faulty_samples,
            axes.missing_flags,
            axes.failing_uncompensated,
            axes.healthy_disturbed,
            tx,
            ty,
            tz
        );
        let injected =
            sensors.faults() + flips_old + flips_new + update.resets + (commands.commands - 1) + axes.faulty_samples;
        hprintln!(
            "faults injected {}, samples lost {}, panics 0, stack_peak_bytes {}",
            injected,
            sensors.samples_lost + axes.samples_lost,
            firmware::board::stack_peak_bytes()
        );
        let ok = sensors.samples_lost == 0
            && sensors.missing_flags == 0
            && sensors.non_finite == 0
            && accepted_old + accepted_new == 0
            && update.booted_invalid == 0
            && update.retry_failures == 0
            && commands.expected_replies == commands.commands
            && commands.switched
            && axes.samples_lost == 0
            && axes.missing_flags == 0
            && axes.healthy_disturbed == 0
            && axes.failing_uncompensated > 0
            && tx == 0
            && tz == 0
            && ty == axes.faulty_samples;
        finish(ok)
    }
}

#[cfg(not(target_os = "none"))]
fn main() {
    eprintln!("qemu-faults runs under qemu-system-arm: use `cargo xtask qemu-faults`");
}
