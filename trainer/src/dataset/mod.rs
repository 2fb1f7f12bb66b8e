//! Training data: rbf-core features per sample, averaged over blocks.
//!
//! Features are computed per sample by [`rbf_core::Compensator::features`], the
//! very function the firmware runs, then averaged with the bias target over
//! blocks (1 s by default) inside each segment. Samples whose features are
//! still warming up or whose temperature is a held value are left out of the
//! averages; blocks with under half their nominal samples are dropped.
//!
//! A streamed run keeps at most [`MAX_BLOCKS_PER_RUN`] blocks: past that,
//! adjacent blocks of a segment are merged in pairs (sample-weighted means)
//! and the run goes on in blocks twice as long, so the memory a fit holds
//! does not grow with the run's length ([`Blocks::merge_pairs`]).
//!
//! Data flow, one file a step:
//!
//! 1. runs: a [`RunSet`] (`run_set.rs`) is the runs a fit learns from, held
//!    in memory (`[Run]`, [`sample_block_means`]) or streamed from files
//!    ([`RunFiles`], `run_files.rs`: one pass per run for every configuration
//!    asked for, the blocks cached until released);
//! 2. samples: a [`BlockBuilder`] (`builder.rs`) takes a run's samples one by
//!    one, computes the features of one configuration (or of up to
//!    [`MAX_GROUP`] that share its filters) and sums them into blocks;
//!    [`RunSet::for_each_sample`] hands the samples themselves to fits whose
//!    sums do not fit in a feature vector ([`SampleVisit`]);
//! 3. block means of feature configurations: [`Blocks`] (`blocks.rs`), merged
//!    in pairs when a run holds too many; configurations whose blocks follow
//!    from another's (a lagged set, a shaped lag bank, a stretch of a plain
//!    bank) are derived from those without another pass (`derive.rs`,
//!    [`block_source`], [`bank_blocks`]);
//! 4. fits: [`crate::fit`] reads the blocks through [`RunSet::block_means`].
//!
//! The thermometers' pairwise gradients and their correlation with the bias
//! (the RLG paper's input selection, `trainer correlate`) are [`gradients`];
//! the settled plateaus of a run (a soak test's figure) are [`plateaus`].

mod blocks;
mod builder;
mod derive;
pub mod gradients;
pub mod plateaus;
mod run_files;
mod run_set;
#[cfg(test)]
mod test_support;

pub use blocks::Blocks;
pub use builder::{BlockBuilder, MAX_BLOCKS_PER_RUN, MAX_GROUP};
pub use derive::{bank_blocks, block_source};
pub use run_files::RunFiles;
pub use run_set::{RunSet, SampleVisit, sample_block_means};
