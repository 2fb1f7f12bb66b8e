//! Reading what comes from outside, bounded and checked: recorded runs
//! ([`run`], parsed on every core by [`chunked`]), their sample rate
//! ([`sampling`]) and physical plausibility ([`plausible`]), the firmware's
//! output frames ([`frames`]), and the opening of every input ([`input`])
//! through the size [`limits`] that keep memory bounded whatever a file holds.

pub mod chunked;
pub mod frames;
pub mod input;
pub mod limits;
pub mod plausible;
pub mod run;
pub mod sampling;
