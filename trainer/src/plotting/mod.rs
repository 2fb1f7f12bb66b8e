//! What the report's and the plan's plots share, below both: the axis
//! ranges and tick labels ([`axes`]) and the PNG encoding of a drawn bitmap
//! ([`png`]).

pub mod axes;
pub mod png;
