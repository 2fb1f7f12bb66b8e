//! Talking to a running unit over its UART (`trainer device`): the health
//! report, a model update, a live recording of its output frames.
//!
//! The wire protocol is the firmware's own (docs/firmware.md, "Output and
//! commands on USART1"): every message is `COBS(payload) 0x00`; the unit
//! sends output frames, command replies, the boot report and the health
//! report on one line, told apart by payload length and tag ([`link`]).
//! The host frames its commands, reads the unit's frames and reports with
//! the wire protocol's crate the firmware encodes with (`gyro-wire`), and
//! checks model blobs as the unit's model store does
//! (`rbf_core::stored_model`), so both ends read every byte the same way
//! without the trainer linking the firmware library.
//!
//! - [`port`]: opening a serial port, errors that name it;
//! - [`link`]: messages in (resynchronised on the next delimiter after
//!   garbage, which is counted), commands out, every wait bounded;
//! - [`status`]: the health report and what it says in words;
//! - [`install`]: a model update, checked before sending and confirmed after;
//! - [`record`]: output frames to a recorded-run CSV as they come.

pub mod install;
pub mod link;
pub mod port;
pub mod record;
pub mod status;
