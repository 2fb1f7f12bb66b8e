//! # firmware-harness: the test harnesses of the IFOG firmware
//!
//! The firmware library (`firmware`) on emulated devices, for the host tests
//! (tests/, e2e-tests) and the QEMU images; neither the board image nor an
//! application of the library ever sees this crate. `no_std`, as the
//! images it builds.
//! - [`replay`]: emulated devices (TMP117, the rate front end) and the recorded-run replayer of the
//!   QEMU replay image;
//! - [`emulated_flash`]: NOR flash in RAM that can lose power mid-operation (QEMU and host tests);
//! - [`fault_injection`]: buses that fail on a schedule and the fault campaigns of the QEMU fault image;
//! - `host_file` (on the MCU): files in QEMU's directory over semihosting;
//! - `qemu` (on the MCU, feature `board-qemu`): what the QEMU board images emulate around
//!   `firmware::board` (the model slots in RAM, the sensors, TIM3 as data-ready, the run's end).
//!
//! The images themselves are in `src/bin/`: `qemu-replay`, `qemu-faults` and the board images
//! under QEMU (`stm32f405-qemu`, `stm32f405-axes-qemu`, `stm32f405-axes-shared-qemu`,
//! `stm32f405-qemu-serve`, `stm32f405-axes-qemu-serve`); docs/firmware.md.
#![cfg_attr(not(test), no_std)]
#![deny(unsafe_code)]

pub mod emulated_flash;
pub mod fault_injection;
pub mod replay;

#[cfg(target_os = "none")]
pub mod host_file;
#[cfg(all(target_os = "none", feature = "board-qemu"))]
pub mod qemu;
