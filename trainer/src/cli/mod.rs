//! The `trainer` command line: one module per subcommand, each holding its
//! clap arguments and a `run` function; shared argument groups in [`common`].
//!
//! A new subcommand is one file here with `pub struct Args` and
//! `pub fn run(Args) -> anyhow::Result<()>`, plus a `mod` line and one line in [`commands!`].

mod batch;
mod blocks;
mod common;
mod compensate;
mod correlate;
mod decode;
mod device;
mod eval;
mod fit;
mod history;
mod inspect;
mod model_arg;
mod plan;
mod report;
mod simulate;
mod toml;
mod values;

use clap::Subcommand;
pub use common::flag_hint;

/// Declares the [`Command`] enum (in this order in `--help`) and its
/// dispatch over the subcommand modules declared above with plain `mod`
/// lines (so rustfmt, clippy and the import-circle check see every file).
macro_rules! commands {
    ($($module:ident => $variant:ident),* $(,)?) => {

        /// The subcommands.
        #[derive(Subcommand, Debug)]
        pub enum Command {
            $(
                #[allow(missing_docs)]
                $variant($module::Args),
            )*
        }

        impl Command {
            /// Runs the subcommand.
            pub fn run(self) -> anyhow::Result<()> {
                match self {
                    $(Command::$variant(a) => $module::run(a),)*
                }
            }
        }
    };
}

commands! {
    fit => Fit,
    compensate => Compensate,
    eval => Eval,
    inspect => Inspect,
    simulate => Simulate,
    decode => Decode,
    report => Report,
    blocks => Blocks,
    correlate => Correlate,
    plan => Plan,
    device => Device,
    batch => Batch,
    history => History,
}
