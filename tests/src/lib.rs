//! Shared helpers of the cross-crate end-to-end tests.

#[cfg(feature = "full")]
pub mod fixtures;
pub mod robustness;

use std::path::{Path, PathBuf};

/// The workspace root (the tests crate sits directly below it).
pub fn workspace_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("tests/ sits in the workspace")
        .to_owned()
}

/// A bundled example run under `examples/data/`.
pub fn example(name: &str) -> PathBuf {
    workspace_root().join("examples/data").join(name)
}
