//! Shared helpers of the end-to-end tests: a synthetic thermal-chamber run
//! generator (until `trainer simulate` lands it is also what writes the bundled
//! example data) and small utilities for driving the `trainer` binary.

pub mod chamber;
