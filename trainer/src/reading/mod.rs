//! Reading what comes from outside, bounded and checked: recorded runs
//! ([`run`], parsed on every core by [`chunked`]), their sample rate
//! ([`sampling`]) and physical plausibility ([`plausible`]), whether a command's runs are
//! different runs ([`distinct`]), the firmware's
//! output frames ([`frames`]), and the opening of every input ([`input`])
//! through the size [`limits`] that keep memory bounded whatever a file holds.

pub mod chunked;
pub mod distinct;
pub mod frames;
pub mod input;
pub mod limits;
pub mod plausible;
pub mod run;
pub mod sampling;
