//! Firmware benchmark board for QEMU (netduinoplus2): instructions per
//! compensated sample for K = 8, 16, 32, 64 Gaussian centres at D = 3, for
//! the multi-scale sets and for a lag bank of five filters (K = 32), and the
//! whole step of a three-axis IMU: three axes sharing one K = 32, D = 3
//! basis (one compensator, the kernels once, three output layers; decoded
//! from a shared-basis blob), and beside it three separate K = 32, D = 3
//! models (one multi-axis blob, one compensator per axis).
//!
//! QEMU runs with `-icount shift=0` (one instruction = 1 ns of virtual time),
//! so SysTick on the 168 MHz core clock counts 0.168 ticks per instruction:
//! instructions = ticks / 0.168. DWT CYCCNT is not emulated. Counts are
//! instructions, not cycles. Run it with `cargo xtask bench-fw`.
#![cfg_attr(target_os = "none", no_std, no_main)]

#[cfg(target_os = "none")]
mod board {
    use cortex_m::peripheral::SYST;
    use cortex_m::peripheral::syst::SystClkSource;
    use cortex_m_rt::entry;
    use cortex_m_semihosting::{debug, hprintln};
    use rbf_core::axis::{Axis, MAX_AXES};
    use rbf_core::blob::MAX_BLOB_LEN;
    use rbf_core::blob::axes::{AxisModels, decode_axes_into, encode_axes};
    use rbf_core::blob::shared_layout::{decode_shared_into, encode_shared};
    use rbf_core::features::{LOOP_THERMOMETER, THERMOMETERS};
    use rbf_core::lag_bank::LagBank;
    use rbf_core::model::{ModelBody, ModelInfo};
    use rbf_core::rbf::{RbfNetwork, RbfParams};
    use rbf_core::response_bank::ResponseBank;
    use rbf_core::shared_basis::{OutputLayer, SharedAxisModels};
    use rbf_core::{
        Compensator, CompensatorConfig, FeatureConfig, FeatureSet, FeatureVector, GyroSample, MAX_CENTERS, Model,
    };

    /// Samples timed per model size.
    const SAMPLES: u32 = 2000;
    /// SysTick ticks per 1000 instructions under `-icount shift=0` at 168 MHz.
    const TICKS_PER_KILO_INSTRUCTION: u64 = 168;
    const D: usize = 3;

    /// The shape of a benchmark model.
    #[derive(Clone, Copy, PartialEq)]
    #[allow(
        clippy::large_enum_variant,
        reason = "a handful of shapes built once at start-up; the set is what the shape names"
    )]
    enum Shape {
        /// The IFOG paper's (T, ΔT, T×ΔT) with Gaussians over all three inputs.
        Paper,
        /// One of the 8-input multi-scale sets with Gaussians over its first input.
        MultiScale(FeatureSet),
        /// A lag bank of five filters (30 s … 7680 s, the trainer's second
        /// ladder), static degree 3: 8 inputs, Gaussians over T̂.
        LagBank,
    }

    /// Writes a benchmarked model's blob into QEMU's working directory
    /// (`name` NUL-terminated), where `cargo xtask bench-fw` times the C
    /// library's step on the same model (rbf-core-c/c/bench.c).
    #[allow(unsafe_code)]
    fn save_blob(name: &str, blob: &[u8]) {
        use cortex_m_semihosting::{nr, syscall};
        // SAFETY: semihosting calls on a NUL-terminated name and a live
        // buffer; QEMU runs with semihosting on (`cargo xtask bench-fw`).
        let written = unsafe {
            let fd = syscall!(OPEN, name.as_ptr(), nr::open::W_TRUNC_BINARY, name.len() - 1);
            let not_written = if fd == usize::MAX {
                blob.len()
            } else {
                syscall!(WRITE, fd, blob.as_ptr(), blob.len())
            };
            if fd != usize::MAX {
                syscall!(CLOSE, fd);
            }
            not_written == 0
        };
        if !written {
            hprintln!("cannot write {}", name.trim_end_matches('\0'));
        }
    }

    /// A deterministic K-centre model of `shape` with values like a real fit's.
    fn model(k: usize, shape: Shape, width: f32) -> Model {
        model_seeded(k, shape, width, 0x2545_f491)
    }

    /// The three axes' models of the three-axis figure, each K = 32, D = 3
    /// (different centres and weights per axis), through a multi-axis blob,
    /// decoded as a firmware decodes them. The capacity is the single-axis
    /// figures' (64): one instantiation of the step, so the figures above
    /// are those of the same code (the per-axis step does not depend on it).
    static mut AXES: AxisModels = AxisModels::EMPTY;

    #[allow(unsafe_code)]
    fn axis_models() -> &'static AxisModels {
        let mut all = AxisModels::<{ MAX_CENTERS }>::EMPTY;
        for (axis, seed) in Axis::ALL.into_iter().zip([0x2545_f491u32, 0x9E37_79B9, 0x1234_5678]) {
            all.insert(axis, model_seeded(32, Shape::Paper, 1.5, seed));
        }
        let mut blob = [0u8; MAX_BLOB_LEN];
        let n = encode_axes(&all, &mut blob).expect("three K = 32 models fit a blob");
        // SAFETY: the only reference to AXES, taken once.
        let axes = unsafe { &mut *core::ptr::addr_of_mut!(AXES) };
        decode_axes_into(axes, &blob[..n]).expect("the blob decodes");
        axes
    }

    /// The shared-basis three-axis model of the three-axis figure: the
    /// basis of the first separate model (K = 32, D = 3), its layer on x and
    /// layers of other weights and linear terms on y and z, through a
    /// shared-basis blob decoded as a firmware decodes it.
    static mut SHARED: SharedAxisModels = SharedAxisModels::EMPTY;

    #[allow(unsafe_code)]
    fn shared_models() -> &'static SharedAxisModels {
        let x = model_seeded(32, Shape::Paper, 1.5, 0x2545_f491);
        let mut all = SharedAxisModels::from_models(&[(Axis::X, &x)]).expect("one basis");
        for (axis, seed) in [(Axis::Y, 0x9E37_79B9u32), (Axis::Z, 0x1234_5678)] {
            let mut state = seed;
            let mut next = || {
                state ^= state << 13;
                state ^= state >> 17;
                state ^= state << 5;
                (state >> 8) as f32 / (1 << 24) as f32 * 4.0 - 2.0
            };
            let mut weights = [0.0f32; 32];
            weights.iter_mut().for_each(|w| *w = 0.05 * next());
            let linear = [0.01 * next(), 0.2 * next(), 0.1 * next()];
            let layer = OutputLayer {
                weights: &weights,
                linear: &linear,
                constant: 0.05 * next(),
            };
            all.assign_layer(axis, &layer).expect("a bounded layer");
        }
        let mut blob = [0u8; MAX_BLOB_LEN];
        let n = encode_shared(&all, &mut blob).expect("a shared-basis blob fits");
        save_blob("bench-axes-shared.bin\0", &blob[..n]);
        // SAFETY: the only reference to SHARED, taken once.
        let shared = unsafe { &mut *core::ptr::addr_of_mut!(SHARED) };
        decode_shared_into(shared, &blob[..n]).expect("the blob decodes");
        shared
    }

    fn model_seeded(k: usize, shape: Shape, width: f32, seed: u32) -> Model {
        let (dims, kernel) = if shape == Shape::Paper { (D, D) } else { (8, 1) };
        let mut state = seed;
        let mut next = || {
            state ^= state << 13;
            state ^= state >> 17;
            state ^= state << 5;
            (state >> 8) as f32 / (1 << 24) as f32 * 4.0 - 2.0
        };
        let mut centers = [0.0f32; MAX_CENTERS * D];
        centers[..k * kernel].iter_mut().for_each(|c| *c = next());
        let mut weights = [0.0f32; MAX_CENTERS];
        weights[..k].iter_mut().for_each(|w| *w = 0.05 * next());
        let (offset, scale, linear, ranges) = match shape {
            Shape::LagBank => (
                [25.0, 300.0, 2000.0, 0.0, 0.0, 0.0, 0.0, 0.0],
                [10.0, 300.0, 8000.0, 0.5, 0.4, 0.3, 0.2, 0.1],
                [0.01, 0.001, 0.0001, 0.2, 0.1, 0.05, 0.02, 0.01],
                [
                    (-10.0, 60.0),
                    (0.0, 1300.0),
                    (-3500.0, 42000.0),
                    (-3.0, 3.0),
                    (-3.0, 3.0),
                    (-3.0, 3.0),
                    (-3.0, 3.0),
                    (-3.0, 3.0),
                ],
            ),
            _ => (
                [25.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
                [10.0, 0.5, 0.4, 0.3, 12.0, 10.0, 8.0, 200.0],
                [0.01, 0.2, 0.1, 0.05, 0.003, 0.002, 0.001, 0.0001],
                [
                    (0.0, 50.0),
                    (-3.0, 3.0),
                    (-3.0, 3.0),
                    (-3.0, 3.0),
                    (-150.0, 150.0),
                    (-150.0, 150.0),
                    (-150.0, 150.0),
                    (-7500.0, 7500.0),
                ],
            ),
        };
        let net = RbfNetwork::new(&RbfParams {
            offset: &offset[..dims],
            scale: &scale[..dims],
            kernel_inputs: kernel,
            centers: &centers[..k * kernel],
            widths: &[width; MAX_CENTERS][..k],
            weights: &weights[..k],
            linear: &linear[..dims],
            constant: 0.05,
        })
        .expect("valid synthetic network");
        let features = match shape {
            Shape::Paper => FeatureConfig::single(FeatureSet::TempRateProduct, 60.0),
            Shape::MultiScale(set) => FeatureConfig::multiscale(set, [60.0, 480.0, 3840.0]),
            Shape::LagBank => {
                let mut bank = LagBank::plain(&[30.0, 120.0, 480.0, 1920.0, 7680.0], 25.0).expect("valid bank");
                bank.coil_lag_min[..5].copy_from_slice(&[-0.5, -2.0, -8.0, -30.0, -100.0]);
                bank.gain_per_c = 0.01;
                bank.gain_per_c2 = 1e-4;
                bank.static_degree = 3;
                (bank.coil_min_c, bank.coil_max_c) = (-10.0, 60.0);
                FeatureConfig::lag_bank(bank)
            }
        };
        Model::new(features, &ranges[..dims], ModelBody::Rbf(net), ModelInfo::default()).expect("valid synthetic model")
    }

    /// A response-bank model as `trainer fit` writes them: 12 filters
    /// (10 s … 11 h), a static cubic, no centres, the linear layer
    /// [c₁ … c₃, 1, 1, 1, 1, 1], every weight row in use.
    fn response_bank_model() -> Model {
        const USED: usize = 12;
        let mut taus = [0.0f32; USED];
        let mut tau = 10.0f32;
        for t in &mut taus {
            *t = tau;
            tau *= 2.124;
        }
        let mut bank = ResponseBank::new(&taus, 25.0, -10.0, 60.0, 3).expect("valid bank");
        for (j, row) in bank.weights.iter_mut().enumerate() {
            for (k, w) in row.iter_mut().take(USED).enumerate() {
                *w = 0.01 * (j as f32 + 1.0) - 0.001 * k as f32;
            }
        }
        let net = RbfNetwork::new(&RbfParams {
            offset: &[0.0; 8],
            scale: &[1.0; 8],
            kernel_inputs: 1,
            centers: &[],
            widths: &[],
            weights: &[],
            linear: &[0.01, -0.001, 1e-5, 1.0, 1.0, 1.0, 1.0, 1.0],
            constant: 0.05,
        })
        .expect("valid synthetic network");
        let ranges = [
            (-35.0, 35.0),
            (0.0, 1225.0),
            (-42875.0, 42875.0),
            (-3.0, 3.0),
            (-100.0, 100.0),
            (-3500.0, 3500.0),
            (-300.0, 300.0),
            (-9000.0, 9000.0),
        ];
        Model::new(
            FeatureConfig::response_bank(bank),
            &ranges,
            ModelBody::Rbf(net),
            ModelInfo::default(),
        )
        .expect("valid synthetic model")
    }

    /// Instructions of the whole per-sample step (`Compensator::process`:
    /// gap and fault logic, feature filters, evaluation, flags) of `model`
    /// on a slow 1-kHz ramp.
    fn step_instructions(model: &Model, config: &CompensatorConfig) -> u64 {
        let mut compensator = Compensator::new();
        let mut temp_c = 20.0f32;
        let start = SYST::get_current();
        for _ in 0..SAMPLES {
            temp_c += 0.0001;
            // The config and the sample are runtime data, as on a board
            // (and in the C library's step, timed against this).
            let sample = core::hint::black_box(GyroSample::new(0.001, 12.5, Some(temp_c)));
            core::hint::black_box(compensator.process(
                Some(core::hint::black_box(model)),
                core::hint::black_box(config),
                &sample,
            ));
        }
        instructions_per_sample(start)
    }

    fn ticks_between(start: u32, end: u32) -> u32 {
        // SysTick counts down and wraps at 24 bits.
        start.wrapping_sub(end) & 0x00FF_FFFF
    }

    /// Instructions per loop iteration since SysTick read `start` ([`SAMPLES`] iterations).
    fn instructions_per_sample(start: u32) -> u64 {
        let ticks = ticks_between(start, SYST::get_current()) as u64;
        ticks * 1000 / TICKS_PER_KILO_INSTRUCTION / SAMPLES as u64
    }

    /// The output frame of every sample (outside the step): postcard, the
    /// CRC-32 of format 2 and COBS, for each frame kind, and the CRC-32 alone
    /// over as many bytes (what format 2 added to format 1).
    fn frame_instructions() {
        use gyro_wire::frame::{self, AxesFrame, AxisOutput, MAX_AXES_FRAME_LEN, MAX_FRAME_LEN, OutputFrame};
        const CRC32: crc::Crc<u32> = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC);
        let sample = |seq: u32| OutputFrame {
            seq,
            rate_dph: 12.5,
            bias_dph: 0.25,
            rate_comp_dph: 12.25,
            temp_c: 25.0 + seq as f32 * 1e-4,
            flags: 0,
        };
        let mut buf = [0u8; MAX_AXES_FRAME_LEN];
        let mut single_len = 0;
        let start = SYST::get_current();
        for seq in 0..SAMPLES {
            let f = core::hint::black_box(sample(1_000_000 + seq));
            single_len = frame::encode(&f, &mut buf[..MAX_FRAME_LEN]).unwrap_or(0);
        }
        let single = instructions_per_sample(start);
        let axis = |seq: u32| AxisOutput {
            rate_dph: 12.5,
            bias_dph: 0.25,
            rate_comp_dph: 12.25,
            temp_c: 25.0 + seq as f32 * 1e-4,
            flags: 0,
        };
        let mut axes_len = 0;
        let start = SYST::get_current();
        for seq in 0..SAMPLES {
            let f = core::hint::black_box(AxesFrame {
                tag: frame::AXES_FRAME_TAG,
                seq: 1_000_000 + seq,
                axis_mask: 0b111,
                axes: [axis(seq), axis(seq + 1), axis(seq + 2)],
            });
            axes_len = frame::encode_axes(&f, &mut buf).unwrap_or(0);
        }
        let axes = instructions_per_sample(start);
        // The CRC-32 over the bytes it covers (payload less the CRC: wire
        // bytes less COBS's code byte, the 0x00 and the CRC's 4).
        let crc_of = |covered: usize| {
            let bytes = [0x5Au8; MAX_AXES_FRAME_LEN];
            let start = SYST::get_current();
            for _ in 0..SAMPLES {
                core::hint::black_box(CRC32.checksum(core::hint::black_box(&bytes[..covered])));
            }
            instructions_per_sample(start)
        };
        let (crc_single, crc_axes) = (crc_of(single_len.saturating_sub(6)), crc_of(axes_len.saturating_sub(6)));
        hprintln!(
            "instructions_per_sample output frame (postcard, CRC-32, COBS; outside the step): single-axis {} ({} B on the wire, CRC-32 {}), three-axis {} ({} B, CRC-32 {})",
            single,
            single_len,
            crc_single,
            axes,
            axes_len,
            crc_axes
        );
    }

    #[entry]
    fn main() -> ! {
        firmware::board::paint_stack();
        let mut core = cortex_m::Peripherals::take().expect("first and only take");
        core.SYST.set_clock_source(SystClkSource::Core);
        core.SYST.set_reload(0x00FF_FFFF);
        core.SYST.clear_current();
        core.SYST.enable_counter();
        let config = CompensatorConfig::for_sample_rate(1000.0);
        // Per model shape: the model evaluation alone (clamping, normalisation,
        // Gaussians, linear terms: `Model::eval`), then the whole per-sample
        // step (`Compensator::process`: gap and fault logic, feature filters,
        // evaluation, flags). The default's shape (the lag bank) first; the last line is the
        // K = 32, D = 3 evaluation figure.
        // (K, the shape, σ): σ = 1.5
        // keeps the shared term a factor (T = 32); σ = 0.5 (T = 284) adds it
        // to every exponent.
        let lagged = Shape::MultiScale(FeatureSet::MultiScaleLagged { coil_lag_min: 40 });
        let runs = [
            (32, Shape::LagBank, 1.5),
            (32, Shape::MultiScale(FeatureSet::MultiScale), 1.5),
            (32, lagged, 1.5),
            (8, Shape::Paper, 1.5),
            (16, Shape::Paper, 1.5),
            (64, Shape::Paper, 1.5),
            (32, Shape::Paper, 0.5),
            (32, Shape::Paper, 1.5),
        ];
        for (k, shape, width) in runs {
            let model = model(k, shape, width);
            let dims = model.features().dims();
            // Evaluation: a slow ramp through the input box, so every call is
            // real work; the same loop without the call measures the harness
            // (input updates, black boxes), which is subtracted.
            let eval = {
                let inputs = |i: u32| {
                    let t = i as f32;
                    let x = [
                        20.0 + 0.01 * t,
                        0.5 - 0.0005 * t,
                        10.0 + 0.003 * t,
                        0.2,
                        4.0,
                        5.0,
                        2.0,
                        100.0,
                    ];
                    FeatureVector::from_values(&x[..dims])
                };
                let start = SYST::get_current();
                for i in 0..SAMPLES {
                    core::hint::black_box(&inputs(core::hint::black_box(i)));
                }
                let harness = instructions_per_sample(start);
                let start = SYST::get_current();
                for i in 0..SAMPLES {
                    let features = inputs(core::hint::black_box(i));
                    core::hint::black_box(core::hint::black_box(&model).eval(core::hint::black_box(&features)));
                }
                instructions_per_sample(start).saturating_sub(harness)
            };
            // The whole step.
            let step = step_instructions(&model, &config);
            if shape == Shape::LagBank {
                hprintln!(
                    "instructions_per_sample lag-bank K={} F=5: {} whole step (the default features: 5 derivative filters, T̂ and its powers, 8 inputs, Gaussians over T̂), evaluation alone {}",
                    k,
                    step,
                    eval
                );
            } else if shape == lagged {
                hprintln!(
                    "instructions_per_sample K={} D=8 (lagged second-order multi-scale set, Gaussians over T̄ = T − L·ΔT₃): evaluation {} whole step {}",
                    k,
                    eval,
                    step
                );
            } else if shape != Shape::Paper {
                hprintln!(
                    "instructions_per_sample K={} D=8 (multi-scale set, Gaussians over T): evaluation {} whole step {}",
                    k,
                    eval,
                    step
                );
            } else if width < 1.0 {
                hprintln!(
                    "instructions_per_sample K={} D=3 sigma={} (narrow: shared term in every exponent): evaluation {} whole step {}",
                    k,
                    width,
                    eval,
                    step
                );
            } else {
                hprintln!(
                    "instructions_per_sample K={} D=3: evaluation {} whole step {}",
                    k,
                    eval,
                    step
                );
            }
            if k == 32 && shape == Shape::Paper && width >= 1.0 {
                let mut blob = [0u8; MAX_BLOB_LEN];
                if let Ok(n) = rbf_core::blob::encode(&model, &mut blob) {
                    save_blob("bench-k32.bin\0", &blob[..n]);
                }
                hprintln!("instructions_per_sample K=32 D=3: {}", eval);
            }
        }
        // The response bank: 16 filters, 7 inputs, no centres.
        hprintln!(
            "instructions_per_sample response-bank F=12: {}",
            step_instructions(&response_bank_model(), &config)
        );
        // Three axes: per sample each axis's compensator runs its own model
        // on its own rate and coil temperature (the multi-axis loop's step).
        let axes = axis_models();
        let mut compensators = [Compensator::new(); MAX_AXES];
        let mut temps_c = [20.0f32, 21.0, 22.0];
        let start = SYST::get_current();
        for _ in 0..SAMPLES {
            for ((axis, compensator), temp_c) in Axis::ALL.into_iter().zip(&mut compensators).zip(&mut temps_c) {
                *temp_c += 0.0001;
                let sample = GyroSample::new(0.001, 12.5, Some(*temp_c));
                let model = core::hint::black_box(axes).get(axis);
                core::hint::black_box(compensator.process_with(model, &config, &sample));
            }
        }
        let separate = instructions_per_sample(start);
        hprintln!(
            "instructions_per_sample axes=3 K=32 D=3 three separate models (a basis per axis, three evaluations): {}",
            separate
        );
        // Three axes sharing one basis: one compensator (one thermometer,
        // one feature computation), the kernels once, three output layers.
        let shared = shared_models();
        let eval = {
            let inputs = |i: u32| {
                let t = i as f32;
                FeatureVector::from_values(&[20.0 + 0.01 * t, 0.5 - 0.0005 * t, 10.0 + 0.003 * t])
            };
            let start = SYST::get_current();
            for i in 0..SAMPLES {
                core::hint::black_box(&inputs(core::hint::black_box(i)));
            }
            let harness = instructions_per_sample(start);
            let start = SYST::get_current();
            for i in 0..SAMPLES {
                let features = inputs(core::hint::black_box(i));
                core::hint::black_box(core::hint::black_box(shared).eval_axes(core::hint::black_box(&features)));
            }
            instructions_per_sample(start).saturating_sub(harness)
        };
        let mut compensator = Compensator::new();
        let mut temp_c = 20.0f32;
        let rates_dph = [12.5f32, -3.0, 7.25];
        let start = SYST::get_current();
        for _ in 0..SAMPLES {
            temp_c += 0.0001;
            let mut temps_c = [None; THERMOMETERS];
            temps_c[LOOP_THERMOMETER] = Some(temp_c);
            core::hint::black_box(compensator.process_shared(
                Some(core::hint::black_box(shared)),
                core::hint::black_box(&config),
                core::hint::black_box(0.001),
                core::hint::black_box(&temps_c),
                core::hint::black_box(&rates_dph),
            ));
        }
        let step = instructions_per_sample(start);
        hprintln!(
            "instructions_per_sample axes=3 K=32 D=3 shared basis: evaluation {} (kernels once, three output layers)",
            eval
        );
        hprintln!("instructions_per_sample axes=3 K=32 D=3: {}", step);
        frame_instructions();
        hprintln!("stack_peak_bytes {}", firmware::board::stack_peak_bytes());
        debug::exit(debug::EXIT_SUCCESS);
        loop {
            cortex_m::asm::wfi();
        }
    }
}

#[cfg(not(target_os = "none"))]
fn main() {
    eprintln!("qemu-bench runs under qemu-system-arm: use `cargo xtask bench-fw`");
}
