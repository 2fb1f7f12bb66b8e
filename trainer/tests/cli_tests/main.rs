//! The `trainer` CLI driven as a user drives it: one test binary for every
//! module below (one link of the trainer and its dependencies instead of one
//! per file; `cargo test --test cli_tests MODULE::` runs one module).

mod common;

mod axes;
mod batch;
mod cli;
mod figures;
mod hostile;
mod messages;
mod plan;
mod reading;
mod recordings;
mod records;
mod response_bank;
mod robustness;
mod soak;
mod transactions;
mod units;
