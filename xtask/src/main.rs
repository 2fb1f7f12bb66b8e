//! `cargo xtask`: project commands that are more than one cargo call.
#![forbid(unsafe_code)]

use std::path::PathBuf;

use clap::{Parser, Subcommand};

/// Project automation: the test suite, QEMU replays, firmware benchmarks.
#[derive(Parser)]
#[command(about, max_term_width = 100)]
struct Cli {
    #[command(subcommand)]
    command: Cmd,
}

/// What every replay takes: the model, the run and where its compensated copy goes.
#[derive(clap::Args)]
struct ReplayArgs {
    /// Model blob written by `trainer fit`.
    #[arg(long, value_name = "MODEL.bin")]
    model: PathBuf,
    /// Recorded run (single- or multi-axis; temp_fault = 1 rows are replayed as a failed
    /// thermometer: the board image's emulated TMP117 NACKs, the C loop reports the fault).
    #[arg(value_name = "RUN.csv")]
    run: PathBuf,
    /// Compensated run to write.
    #[arg(short, long, value_name = "OUT.csv")]
    output: PathBuf,
    /// Replace outputs that exist (as `trainer compensate --force`).
    #[arg(long)]
    force: bool,
}

impl ReplayArgs {
    /// What `--force` makes of outputs that exist.
    fn existing(&self) -> trainer::output::Existing {
        trainer::output::Existing::from_force(self.force)
    }
}

#[derive(Subcommand)]
enum Cmd {
    /// Run the whole test suite as CI does: fmt check, import circles, the C header's drift,
    /// clippy -D warnings (host and firmware), the no_std check of rbf-core, the firmware
    /// builds, the panic-free checks, host tests and the QEMU and C library tests. Installs the
    /// thumbv7em target, rustfmt, clippy, qemu-system-arm, gcc-arm-none-eabi and
    /// libnewlib-arm-none-eabi when missing.
    Ci,
    /// Replay a recorded run through the real firmware image under QEMU
    /// (netduinoplus2 = STM32F405): the model goes into flash slot MODEL_A, the
    /// run is read and the output written over semihosting. The output is
    /// byte-identical to `trainer compensate --model MODEL.bin RUN.csv -o OUT.csv`,
    /// and what compensate refuses, the replay refuses (it runs compensate's checks first).
    QemuReplay {
        #[command(flatten)]
        replay: ReplayArgs,
        /// Also write the UART output frames (decode with `trainer decode`).
        #[arg(long, value_name = "FRAMES.bin")]
        frames: Option<PathBuf>,
        /// Accept a run where no row could be compensated (as `trainer compensate`).
        #[arg(long)]
        allow_uncompensated: bool,
        /// Accept a run implausible as a gyro recording (as `trainer compensate`).
        #[arg(long)]
        allow_implausible: bool,
    },
    /// Replay a recorded run through rbf-core's C library: the C program
    /// rbf-core-c/c/replay.c built from the header and the static library with the
    /// host's cc (or, with --qemu, with arm-none-eabi-gcc and newlib for the
    /// STM32F405, run under QEMU's netduinoplus2). The output is byte-identical to
    /// `trainer compensate --model MODEL.bin RUN.csv -o OUT.csv`; a blob the
    /// library refuses ends it with the library's words and a non-zero exit.
    ///
    /// Example: cargo xtask c-replay --qemu --model model.bin run.csv -o out.csv
    CReplay {
        /// Build for the STM32F405 and run under QEMU (installs
        /// gcc-arm-none-eabi, libnewlib-arm-none-eabi and qemu-system-arm when missing).
        #[arg(long)]
        qemu: bool,
        #[command(flatten)]
        replay: ReplayArgs,
    },
    /// Write rbf-core-c/include/rbf_core.h, the C library's header, from the
    /// crate's source with cbindgen (CI fails when the checked-in one drifts).
    CHeader,
    /// Run the gyro board without hardware: the stm32f405 board image under
    /// QEMU with USART1 on a pseudo-terminal, at its 1-kHz sample rate, its
    /// front ends and thermometers emulated (a built-in temperature ramp, or
    /// the rows of --run RUN.csv).
    /// Prints `pty: PATH` on a line of its own and serves until stopped
    /// (Ctrl-C); `trainer device status|update|record --port PATH` talks to it.
    ///
    /// Example: cargo xtask qemu-board --pty
    QemuBoard {
        /// The three-axis IMU board (stm32f405-axes-qemu-serve: one frame with x, y, z per sample).
        #[arg(long, value_name = "N", default_value_t = 1,
              value_parser = clap::value_parser!(u8).range(1..=3))]
        axes: u8,
        /// A model blob in flash slot A at boot (without one the board runs
        /// uncompensated, flag 4, until `trainer device update` installs one).
        #[arg(long, value_name = "MODEL.bin")]
        model: Option<PathBuf>,
        /// A recorded run the emulated front ends and thermometers answer
        /// from, one row per sample, from its start again at its end
        /// (three-axis with --axes 3: rate_x_dph, temp_x_c, …).
        #[arg(long, value_name = "RUN.csv")]
        run: Option<PathBuf>,
        /// Put USART1 on a pseudo-terminal (the only way this command serves).
        #[arg(long, required = true)]
        pty: bool,
    },
    /// Count instructions per compensated sample in QEMU (-icount shift=0,
    /// SysTick) for K = 8, 16, 32, 64 centres at D = 3, the multi-scale sets
    /// and a five-filter lag bank; run the stm32f405 board's own main loop
    /// under QEMU through a model update and a bench command
    /// (`board_stack_peak_bytes N`); report flash/RAM of the images. The last
    /// line is `instructions_per_sample K=32 D=3: N`.
    BenchFw,
    /// List the import circles among each crate's modules (rbf-core,
    /// firmware, trainer, xtask): modules that import each other, directly
    /// or round a loop, with the imports that tie them. Fails if there is
    /// one; `cargo xtask ci` runs it.
    ImportCircles,
    /// Build the stm32f405 board image and prove from its machine code that
    /// no panic is reachable from its loop and interrupt handlers (part of
    /// `ci`; docs/panic-free.md).
    CheckBoardPanics,
    /// Prove at link time that no panic is reachable from any function of the C
    /// library (rbf-core-c) on the MCU target, and that the check can fail (part of `ci`).
    CheckCLibraryPanics,
    /// Run the stm32f405 board's own driver and loop code on the host against
    /// simulated peripherals that fail (stuck SDA, NACK storm, late sensors,
    /// data-ready faults, a 4-s flash erase at 47 kHz LSI, flash errors, RX
    /// noise, a loop stall): one line per scenario, then `board faults: N
    /// scenarios, M failed`; fails when any scenario fails (part of `ci`).
    BoardFaults,
    /// The default fit on recorded gyros of other designs: each trained on its
    /// planned run and its cycle, verified on its random and field histories
    /// (100-s cluster STD against ref_dph), beside the fit's forecast.
    BenchDesigns {
        /// Directory of NAME_planned.csv, NAME_cycle.csv, NAME_random.csv, NAME_field.csv.
        #[arg(long, value_name = "DIR", default_value = "../shared/data/other-designs")]
        dir: PathBuf,
        /// Judge this trainer instead of this workspace's release build.
        #[arg(long, value_name = "PATH")]
        trainer: Option<PathBuf>,
        /// Options for `trainer fit` instead of the default model, as one string,
        /// e.g. --fit-args="--features lag-bank".
        #[arg(long, value_name = "ARGS", allow_hyphen_values = true)]
        fit_args: Option<String>,
    },
    /// Accuracy against the peers: on simulated chamber runs of both protocols
    /// (trained on one 1 °C/min run, verified at other ramp rates and on a random
    /// profile) compare no compensation, poly3, rbf2, the IFOG paper's rbf, the
    /// default, and scikit-learn SVR and KernelRidge on the same features (in a
    /// venv it makes under target/). Then in use: on four plants (the documented
    /// gyro, units 1 and 2, another mechanical design; --units and --designs add
    /// more) the default trained on the 12-h planned run, the 1 °C/min cycle and
    /// the designed run alone, verified on two random set-point runs and two
    /// field histories, beside a lag-bank least-squares reference, the fit's
    /// forecast and each run's noise ceiling. Prints improvement %, residual
    /// 100-s STD, fit time, and which plants miss issue 32's targets.
    BenchAccuracy {
        /// Simulate another gyro in the chamber protocols (`trainer simulate
        /// --params`), e.g. bench/accuracy/another-gyro.json: does the default
        /// generalise to a thermal model it was not developed on?
        #[arg(long, value_name = "FILE.json")]
        params: Option<PathBuf>,
        /// Only the in-use section (train on a chamber run, verify in use).
        #[arg(long)]
        in_use: bool,
        /// In-use section on two plants (the documented gyro and unit 1).
        #[arg(long)]
        quick: bool,
        /// In-use section: also units 3 … N of `trainer simulate --unit`
        /// (plants the default was not developed on).
        #[arg(long, value_name = "N", default_value_t = 0)]
        units: u64,
        /// In-use section: also designs 1 … N of `trainer simulate --design` (gyros of
        /// other mechanical designs, drawn from ranges as wide as real ones).
        #[arg(long, value_name = "N", default_value_t = 0)]
        designs: u64,
        /// Write the in-use section's results as JSON (`-`: stdout).
        #[arg(long, value_name = "FILE")]
        json: Option<PathBuf>,
        /// In-use section: judge this trainer's fit and compensate (e.g. another
        /// branch's build); the simulator stays this workspace's.
        #[arg(long, value_name = "PATH")]
        trainer: Option<PathBuf>,
        /// In-use section: options for `trainer fit` instead of the default model,
        /// as one string, e.g. --fit-args="--method poly3".
        #[arg(long, value_name = "ARGS", allow_hyphen_values = true)]
        fit_args: Option<String>,
        /// In-use section: the planned chamber run every plant is trained on (time_s,chamber_c
        /// set points, as `trainer plan` writes them); default: `trainer plan --min-c -40
        /// --max-c 60 --max-rate-c-per-min 5 --hours 12`.
        #[arg(long, value_name = "PLAN.csv")]
        plan: Option<PathBuf>,
        /// In-use section: train every plant on the default plan drawn with seeds 1 … N, each
        /// its own planned column; the targets read the means over them. One plan's draw
        /// moves a design's planned score by several points (docs/benchmarks.md): judge a
        /// model change on more than one.
        #[arg(long, value_name = "N", default_value_t = 1, conflicts_with = "plan",
              value_parser = clap::value_parser!(u64).range(1..=9))]
        plan_seeds: u64,
        /// In-use section: train every plant on the default plan of each of these lengths, h
        /// (with every --plan-seeds seed), e.g. --plan-hours 12,24 for issue 48's two plans;
        /// a table judges each length on the worse of two soak tests (≤ 0.03 °/h after 12 h, ≤ 0.01 after
        /// 24 h), in use (mean ≥ 93 %) and the forecast (within ×1.5).
        #[arg(long, value_name = "H,H…", value_delimiter = ',', default_value = "12",
              conflicts_with = "plan", value_parser = plan_hours)]
        plan_hours: Vec<f64>,
    },
    /// Fault injection on the firmware image under QEMU: 20,000 samples through the
    /// real drivers with I2C NACK bursts, stuck readings, a stuck bus, spikes,
    /// out-of-range temperatures, SPI errors, NaN rates and corrupted front-end
    /// samples; every single-bit flip of both blobs; a reset after every flash
    /// operation of a model update (emulated flash); bad and good UART commands.
    /// Ends with `faults injected N, samples lost 0, panics 0`.
    QemuFaults {
        /// Model running at boot (flash slot MODEL_A).
        #[arg(long, value_name = "MODEL.bin")]
        model: PathBuf,
        /// Model the update installs (placed in MODEL_B for the image to read).
        #[arg(long, value_name = "UPDATE.bin")]
        update: PathBuf,
    },
    /// Large-run throughput: generates a 20-h, 100-Hz chamber run (7.2 million
    /// rows) with `trainer simulate`, then times `trainer fit` and a pandas +
    /// scikit-learn pipeline doing the same job (read, 1-s means, features,
    /// kernel ridge with a small grid search; bench/large-run/) one after the
    /// other, with each one's peak memory. The venv is made under target/.
    BenchLargeRun {
        /// Then time `trainer fit` and `trainer compensate` on the 20-h run and
        /// `trainer fit` on the 2-h run N more times each and print the median
        /// and range of wall time and peak memory (one run is noisy on a shared
        /// machine).
        #[arg(long, value_name = "N", default_value_t = 0)]
        repeat: u32,
    },
    /// Production-batch throughput: 32 simulated units of four designs (a 17-h planned
    /// run at 10 Hz each to train on, a 4-h cycle to hold out; generated once under
    /// target/bench-batch/), one `trainer batch` without records and one with records in
    /// SQLite; prints units per minute, peak memory and the time the summaries and
    /// records take.
    BenchBatch {
        /// The trainer to time (default: a release build).
        #[arg(long, value_name = "PATH")]
        trainer: Option<PathBuf>,
    },
    /// Fuzz everything that reads outside input (model blobs, recorded runs,
    /// output frames) with libFuzzer via cargo fuzz (installed when missing),
    /// each target for --seconds, from a seed corpus written by the current
    /// encoders. Prints executions, corpus size and findings per target; fails
    /// if any input breaks a target (reproducers in target/fuzz/artifacts/).
    Fuzz {
        /// Seconds per target.
        #[arg(long, default_value_t = 60)]
        seconds: u32,
    },
}

fn main() -> anyhow::Result<()> {
    match Cli::parse().command {
        Cmd::Ci => xtask::ci::ci(),
        Cmd::QemuReplay {
            replay,
            frames,
            allow_uncompensated,
            allow_implausible,
        } => {
            xtask::qemu::ensure_installed()?;
            let accept = trainer::evaluation::axes::Acceptance {
                uncompensated: allow_uncompensated,
                implausible: allow_implausible,
            };
            let summary = xtask::replay::qemu_replay_checked(
                &replay.model,
                &replay.run,
                &replay.output,
                frames.as_deref(),
                replay.existing(),
                accept,
            )
            .map_err(xtask::replay::with_flag_hint)?;
            println!(
                "wrote {} ({} rows); firmware: {}",
                replay.output.display(),
                summary.samples,
                summary.report
            );
            Ok(())
        }
        Cmd::QemuBoard {
            axes,
            model,
            run,
            pty: _,
        } => {
            anyhow::ensure!(axes != 2, "--axes 2: the boards are single-axis (1) or three-axis (3)");
            xtask::qemu::ensure_installed()?;
            xtask::qemu_board::serve(&xtask::qemu_board::BoardOptions {
                three_axes: axes == 3,
                model,
                run,
                limit: None,
            })
        }
        Cmd::CReplay { qemu, replay } => {
            let target = if qemu {
                xtask::c_library::CTarget::Qemu
            } else {
                xtask::c_library::CTarget::Host
            };
            let summary = xtask::c_replay::c_replay(
                target,
                &replay.model,
                &replay.run,
                &replay.output,
                replay.existing(),
                trainer::evaluation::axes::Acceptance::default(),
            )
            .map_err(xtask::replay::with_flag_hint)?;
            println!("wrote {}; {}", replay.output.display(), summary.report);
            Ok(())
        }
        Cmd::CHeader => {
            println!("wrote {}", xtask::c_library::write_header()?.display());
            Ok(())
        }
        Cmd::BenchFw => xtask::bench::bench_fw(),
        Cmd::ImportCircles => xtask::import_circles::import_circles(),
        Cmd::CheckBoardPanics => xtask::firmware::check_board_panics(),
        Cmd::CheckCLibraryPanics => xtask::c_library::check_panic_free(),
        Cmd::BoardFaults => xtask::board_faults::board_faults(),
        Cmd::BenchDesigns { dir, trainer, fit_args } => {
            let trainer = match trainer {
                Some(t) => std::path::absolute(t)?,
                None => {
                    xtask::run("cargo", &["build", "--release", "--quiet", "--package", "trainer"])?;
                    xtask::release_trainer()
                }
            };
            let fit_args: Vec<String> = fit_args
                .iter()
                .flat_map(|a| a.split_whitespace())
                .map(str::to_owned)
                .collect();
            xtask::accuracy::designs::bench_designs(&dir, &trainer, &fit_args)
        }
        Cmd::BenchAccuracy {
            params,
            in_use,
            quick,
            units,
            designs,
            json,
            trainer,
            fit_args,
            plan,
            plan_seeds,
            plan_hours,
        } => xtask::accuracy::bench_accuracy(&xtask::accuracy::AccuracyOptions {
            params,
            in_use_only: in_use,
            in_use: xtask::accuracy::in_use::InUseOptions {
                quick,
                units,
                designs,
                trainer: trainer.map(std::path::absolute).transpose()?,
                fit_args: fit_args
                    .iter()
                    .flat_map(|a| a.split_whitespace())
                    .map(str::to_owned)
                    .collect(),
                plan: plan.map(std::path::absolute).transpose()?,
                plan_seeds,
                plan_hours,
            },
            json,
        }),
        Cmd::QemuFaults { model, update } => {
            xtask::qemu::ensure_installed()?;
            for line in xtask::faults::qemu_faults(&model, &update)? {
                println!("{line}");
            }
            Ok(())
        }
        Cmd::BenchLargeRun { repeat } => xtask::large_run::bench_large_run(repeat),
        Cmd::BenchBatch { trainer } => xtask::bench_batch::bench_batch(trainer.as_deref()),
        Cmd::Fuzz { seconds } => xtask::fuzz::fuzz(seconds).map(|_| ()),
    }
}

/// A plan length of `--plan-hours`, h: finite and within what `trainer plan` designs (0 … 168 h).
fn plan_hours(text: &str) -> Result<f64, String> {
    let hours: f64 = text.trim().parse().map_err(|e| format!("{text:?}: {e}"))?;
    if hours.is_finite() && hours > 0.0 && hours <= 168.0 {
        Ok(hours)
    } else {
        Err(format!("{text}: a plan is longer than 0 h and at most 168 h"))
    }
}
