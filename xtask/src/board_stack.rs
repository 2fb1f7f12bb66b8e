//! The gyro board's own stack peak, measured under QEMU: the
//! `stm32f405-qemu` image (the board's main loop, interrupt handlers
//! and drivers; the clock setup and the pieces QEMU lacks swapped, see
//! docs/firmware.md) boots with a model in flash slot A, receives a model
//! update and a `bench` command over its UART (this module plays the host:
//! it reads the output frames and sends the commands), runs at least 10,000
//! samples and reports `board_stack_peak_bytes N` from its painted stack.

use std::io::{Read, Write};
use std::os::unix::net::UnixStream;
use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::{AtomicU8, AtomicU32, AtomicUsize, Ordering};
use std::time::{Duration, Instant};

use anyhow::{Context, bail};
use rbf_core::axis::Axis;
use rbf_core::blob::axes::AxisModels;
use rbf_core::lag_bank::LagBank;
use rbf_core::model::{ModelBody, ModelInfo};
use rbf_core::rbf::{RbfNetwork, RbfParams};
use rbf_core::shared_basis::SharedAxisModels;
use rbf_core::{FeatureConfig, FeatureSet, Model};

use crate::replay::MODEL_SLOT_A;
use crate::{firmware, qemu};

/// Output frames the host waits for before it sends the update (boot is over).
const FRAMES_BEFORE_UPDATE: usize = 200;

/// Command bytes sent per output frame the board has sent: what a 160-kbaud
/// line gives a board sampling at 1 kHz. QEMU's socket delivers as fast as
/// the host runs, which a loaded host makes many times faster than the
/// guest drains its 256-byte receive queue between samples (bytes lost, the
/// install refused or malformed); paced by the guest's own frames, the
/// queue sees what a real line gives it, however loaded the host.
const COMMAND_BYTES_PER_FRAME: usize = 16;
/// No reply status seen yet.
const NO_REPLY: u8 = u8::MAX;

/// What the board run reported.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct BoardRun {
    /// Deepest stack use, bytes.
    pub stack_peak_bytes: u64,
    /// The image's own summary line (samples, missed, output errors, update status).
    pub summary: String,
    /// Output frames the host received.
    pub frames: usize,
    /// Steps the bench command's report counted (its cycle counts are 0
    /// under QEMU, which has no cycle counter).
    pub bench_steps: u32,
}

/// A K = 32 network over `dims` inputs with Gaussians over the first
/// `kernel` (values like a real fit's, shared width).
fn network(dims: usize, kernel: usize, scale: &[f32]) -> anyhow::Result<RbfNetwork<64, 12>> {
    network_of(32, 0x2545_f491, dims, kernel, scale)
}

/// [`network`] with `k` centres and its values drawn from `seed`.
fn network_of(k: usize, seed: u32, dims: usize, kernel: usize, scale: &[f32]) -> anyhow::Result<RbfNetwork<64, 12>> {
    network_weighted(k, seed, seed, dims, kernel, scale)
}

/// [`network_of`] with its centres drawn from `seed`, its weights from
/// `weight_seed` (networks of one basis with their own output layers).
fn network_weighted(
    k: usize,
    seed: u32,
    weight_seed: u32,
    dims: usize,
    kernel: usize,
    scale: &[f32],
) -> anyhow::Result<RbfNetwork<64, 12>> {
    let draw = |mut state: u32| {
        move || {
            state ^= state << 13;
            state ^= state >> 17;
            state ^= state << 5;
            (state >> 8) as f32 / (1 << 24) as f32 * 4.0 - 2.0
        }
    };
    let mut next = draw(seed);
    let centers: Vec<f32> = (0..k * kernel).map(|_| next()).collect();
    if weight_seed != seed {
        next = draw(weight_seed);
    }
    let weights: Vec<f32> = (0..k).map(|_| 0.05 * next()).collect();
    let mut offset = vec![0.0; dims];
    offset[0] = 25.0;
    RbfNetwork::new(&RbfParams {
        offset: &offset,
        scale,
        kernel_inputs: kernel,
        centers: &centers,
        widths: &vec![1.5; k],
        weights: &weights,
        linear: &vec![0.01; dims],
        constant: 0.05,
    })
    .map_err(|e| anyhow::anyhow!("synthetic network: {e}"))
}

/// The model at boot: the IFOG paper's (T, ΔT, T×ΔT), K = 32.
fn boot_model() -> anyhow::Result<Model> {
    let net = network(3, 3, &[10.0, 0.5, 12.0])?;
    let features = FeatureConfig::single(FeatureSet::TempRateProduct, 60.0);
    let ranges = [(0.0, 50.0), (-3.0, 3.0), (-150.0, 150.0)];
    Model::new(features, &ranges, ModelBody::Rbf(net), ModelInfo::default()).map_err(|e| anyhow::anyhow!("{e}"))
}

/// The update: a lag bank of five filters, K = 32 over T̂.
fn update_model() -> anyhow::Result<Model> {
    lag_bank_model(32, 0x2545_f491)
}

/// A lag bank of five filters with `k` centres over T̂, its values drawn from `seed`.
fn lag_bank_model(k: usize, seed: u32) -> anyhow::Result<Model> {
    lag_bank_weighted(k, seed, seed)
}

/// [`lag_bank_model`] with its weights drawn from `weight_seed`.
fn lag_bank_weighted(k: usize, seed: u32, weight_seed: u32) -> anyhow::Result<Model> {
    let scale = [10.0, 300.0, 8000.0, 0.5, 0.4, 0.3, 0.2, 0.1];
    let net = network_weighted(k, seed, weight_seed, 8, 1, &scale)?;
    let mut bank = LagBank::plain(&[30.0, 120.0, 480.0, 1920.0, 7680.0], 25.0).context("bank")?;
    bank.coil_lag_min[..5].copy_from_slice(&[-0.5, -2.0, -8.0, -30.0, -100.0]);
    bank.static_degree = 3;
    (bank.coil_min_c, bank.coil_max_c) = (-10.0, 60.0);
    let mut ranges = vec![(-10.0, 60.0), (0.0, 1300.0), (-3500.0, 42000.0)];
    ranges.resize(8, (-3.0, 3.0));
    let features = FeatureConfig::lag_bank(bank);
    Model::new(features, &ranges, ModelBody::Rbf(net), ModelInfo::default()).map_err(|e| anyhow::anyhow!("{e}"))
}

fn encode(model: &Model) -> anyhow::Result<Vec<u8>> {
    let mut blob = vec![0u8; rbf_core::blob::MAX_BLOB_LEN];
    let n = rbf_core::blob::encode(model, &mut blob).map_err(|e| anyhow::anyhow!("{e}"))?;
    blob.truncate(n);
    Ok(blob)
}

/// The three-axis board's models at boot: per axis the paper's (T, ΔT,
/// T×ΔT) with as many centres as the board holds
/// ([`firmware_lib::AXIS_CENTERS`]), each axis its own values.
fn boot_axes() -> anyhow::Result<Vec<u8>> {
    let mut axes = Box::new(AxisModels::<64>::EMPTY);
    for (axis, seed) in Axis::ALL.into_iter().zip([0x2545_f491, 0x9E37_79B9, 0x1234_5678]) {
        let net = network_of(firmware_lib::AXIS_CENTERS, seed, 3, 3, &[10.0, 0.5, 12.0])?;
        let features = FeatureConfig::single(FeatureSet::TempRateProduct, 60.0);
        let ranges = [(0.0, 50.0), (-3.0, 3.0), (-150.0, 150.0)];
        let model = Model::new(features, &ranges, ModelBody::Rbf(net), ModelInfo::default())
            .map_err(|e| anyhow::anyhow!("{e}"))?;
        axes.insert(axis, model);
    }
    encode_axes_blob(&axes)
}

/// The three-axis board's update: per axis a lag bank of five filters
/// with [`firmware_lib::AXIS_CENTERS`] centres over T̂.
fn update_axes() -> anyhow::Result<Vec<u8>> {
    let mut axes = Box::new(AxisModels::<64>::EMPTY);
    for (axis, seed) in Axis::ALL.into_iter().zip([0x0BAD_CAFE, 0x2545_f491, 7]) {
        axes.insert(axis, lag_bank_model(firmware_lib::AXIS_CENTERS, seed)?);
    }
    encode_axes_blob(&axes)
}

/// The shared-basis board's model at boot and its update: one basis of
/// [`firmware_lib::SHARED_AXIS_CENTERS`] centres (the paper's (T, ΔT,
/// T×ΔT) at boot, a lag bank of five filters over T̂ for the update) with
/// each axis's own output layer.
fn shared_axes(update: bool) -> anyhow::Result<Vec<u8>> {
    let k = firmware_lib::SHARED_AXIS_CENTERS;
    let mut models = Vec::new();
    for weight_seed in [0x0BAD_CAFE, 0x9E37_79B9, 7] {
        let model = if update {
            lag_bank_weighted(k, 0x2545_f491, weight_seed)?
        } else {
            let net = network_weighted(k, 0x2545_f491, weight_seed, 3, 3, &[10.0, 0.5, 12.0])?;
            let features = FeatureConfig::single(FeatureSet::TempRateProduct, 60.0);
            let ranges = [(0.0, 50.0), (-3.0, 3.0), (-150.0, 150.0)];
            Model::new(features, &ranges, ModelBody::Rbf(net), ModelInfo::default())
                .map_err(|e| anyhow::anyhow!("{e}"))?
        };
        models.push(model);
    }
    let pairs: Vec<(Axis, &Model)> = Axis::ALL.into_iter().zip(&models).collect();
    let shared = SharedAxisModels::from_models(&pairs).map_err(|e| anyhow::anyhow!("shared basis: {e}"))?;
    let mut blob = vec![0u8; rbf_core::blob::MAX_BLOB_LEN];
    let n = rbf_core::blob::shared_layout::encode_shared(&shared, &mut blob).map_err(|e| anyhow::anyhow!("{e}"))?;
    blob.truncate(n);
    Ok(blob)
}

fn encode_axes_blob(axes: &AxisModels<64>) -> anyhow::Result<Vec<u8>> {
    let mut blob = vec![0u8; rbf_core::blob::MAX_BLOB_LEN];
    let n = rbf_core::blob::axes::encode_axes(axes, &mut blob).map_err(|e| anyhow::anyhow!("{e}"))?;
    blob.truncate(n);
    Ok(blob)
}

/// Builds the `stm32f405-qemu` image and runs it as the module docs say.
pub fn measure() -> anyhow::Result<BoardRun> {
    measure_image(firmware::BOARD_QEMU, encode(&boot_model()?)?, encode(&update_model()?)?)
}

/// [`measure`] for the three-axis board (`stm32f405-axes-qemu`): a multi-axis blob
/// at boot and a multi-axis update, one frame per sample with every axis.
pub fn measure_axes() -> anyhow::Result<BoardRun> {
    measure_image(firmware::BOARD_AXES_QEMU, boot_axes()?, update_axes()?)
}

/// [`measure`] for the shared-basis three-axis board
/// (`stm32f405-axes-shared-qemu`): a shared-basis blob at boot and a shared-basis
/// update, one frame per sample with every axis.
pub fn measure_axes_shared() -> anyhow::Result<BoardRun> {
    measure_image(
        firmware::BOARD_AXES_SHARED_QEMU,
        shared_axes(false)?,
        shared_axes(true)?,
    )
}

fn measure_image(image: firmware::BoardImage, boot: Vec<u8>, update: Vec<u8>) -> anyhow::Result<BoardRun> {
    let built = image.build()?;
    let dir = tempfile::TempDir::new()?;
    let elf = dir.path().join(image.bin);
    std::fs::copy(&built, &elf).context("copy the QEMU board image")?;
    std::fs::write(dir.path().join("boot.bin"), boot)?;
    let mut commands = vec![0u8; gyro_wire::command::MAX_COMMAND_FRAME_LEN];
    let n = gyro_wire::command::encode_install_command(&update, &mut commands).context("encode the command")?;
    commands.truncate(n);
    let mut bench = [0u8; 4];
    let n = gyro_wire::cobs::cobs_encode(&[gyro_wire::command::CMD_BENCH], &mut bench).context("bench command")?;
    commands.extend_from_slice(&bench[..n]);
    run(&elf, dir.path(), &commands)
}

fn run(elf: &Path, dir: &Path, command: &[u8]) -> anyhow::Result<BoardRun> {
    let extra = [
        "-icount".to_owned(),
        "shift=0,sleep=off".to_owned(),
        "-device".to_owned(),
        format!("loader,file=boot.bin,addr={MODEL_SLOT_A:#x}"),
        "-chardev".to_owned(),
        "socket,id=uart,path=uart.sock,server=on,wait=on".to_owned(),
    ];
    let child = qemu::spawn(elf, dir, "chardev:uart", &extra)?;
    // QEMU waits for this connection before it starts the guest.
    let started = Instant::now();
    let mut uart = loop {
        match UnixStream::connect(dir.join("uart.sock")) {
            Ok(stream) => break stream,
            Err(_) if started.elapsed() < Duration::from_secs(10) => std::thread::sleep(Duration::from_millis(20)),
            Err(e) => return Err(e).context("cannot connect to QEMU's UART socket"),
        }
    };
    let frames = Arc::new(AtomicUsize::new(0));
    let reply = Arc::new(AtomicU8::new(NO_REPLY));
    let bench_steps = Arc::new(AtomicU32::new(0));
    let reader = {
        let heard = Heard {
            frames: frames.clone(),
            reply: reply.clone(),
            bench_steps: bench_steps.clone(),
        };
        let mut uart = uart.try_clone()?;
        std::thread::spawn(move || read_frames(&mut uart, &heard))
    };
    while frames.load(Ordering::Relaxed) < FRAMES_BEFORE_UPDATE && started.elapsed() < Duration::from_secs(60) {
        std::thread::sleep(Duration::from_millis(5));
    }
    // Paced by the guest's own frames (see COMMAND_BYTES_PER_FRAME).
    for chunk in command.chunks(COMMAND_BYTES_PER_FRAME) {
        let seen = frames.load(Ordering::Relaxed);
        uart.write_all(chunk).context("send the install command")?;
        let sent = Instant::now();
        while frames.load(Ordering::Relaxed) == seen && sent.elapsed() < Duration::from_secs(10) {
            std::thread::sleep(Duration::from_millis(1));
        }
    }
    let result = qemu::wait(child, dir, Duration::from_secs(300))?;
    drop(uart);
    let _ = reader.join();
    let peak = result
        .log
        .lines()
        .find_map(|l| l.strip_prefix("board_stack_peak_bytes "))
        .and_then(|n| n.trim().parse::<u64>().ok());
    let summary = result
        .log
        .lines()
        .find(|l| l.starts_with("samples "))
        .unwrap_or("")
        .to_owned();
    let reply = reply.load(Ordering::Relaxed);
    let bench_steps = bench_steps.load(Ordering::Relaxed);
    match peak {
        Some(stack_peak_bytes) if result.success && reply == 0 && bench_steps == firmware_lib::bench::BENCH_STEPS => {
            Ok(BoardRun {
                stack_peak_bytes,
                summary,
                frames: frames.load(Ordering::Relaxed),
                bench_steps,
            })
        }
        _ => bail!(
            "the QEMU board run failed (update reply status {reply}, bench report of {bench_steps} steps, {} frames):\n{}",
            frames.load(Ordering::Relaxed),
            result.log
        ),
    }
}

/// What the host heard from the board.
struct Heard {
    frames: Arc<AtomicUsize>,
    /// Status of the install reply ([`NO_REPLY`] before one).
    reply: Arc<AtomicU8>,
    /// Steps of the bench report (0 before one).
    bench_steps: Arc<AtomicU32>,
}

/// Reads COBS frames from the board until the socket closes: counts them,
/// keeps the status of an install reply (`[0x01, status]`) and the step
/// count of a bench report.
fn read_frames(uart: &mut UnixStream, heard: &Heard) {
    use gyro_wire::bench::{BENCH_REPORT_LEN, BenchReport};
    use gyro_wire::cobs::cobs_decode_in_place;
    use gyro_wire::command::{CMD_INSTALL_MODEL, REPLY_LEN};
    let mut frame = Vec::new();
    let mut buf = [0u8; 4096];
    while let Ok(n) = uart.read(&mut buf) {
        if n == 0 {
            break;
        }
        for &byte in &buf[..n] {
            if byte != 0 {
                frame.push(byte);
                continue;
            }
            heard.frames.fetch_add(1, Ordering::Relaxed);
            match cobs_decode_in_place(&mut frame) {
                Some(REPLY_LEN) if frame[0] == CMD_INSTALL_MODEL => {
                    heard.reply.store(frame[1], Ordering::Relaxed);
                }
                Some(BENCH_REPORT_LEN) => {
                    if let Some(report) = BenchReport::from_bytes(&frame[..BENCH_REPORT_LEN]) {
                        heard.bench_steps.store(report.steps, Ordering::Relaxed);
                    }
                }
                _ => {}
            }
            frame.clear();
        }
    }
}
