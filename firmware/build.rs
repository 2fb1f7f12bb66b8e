//! Puts the workspace `memory.x` on the linker path and links with
//! cortex-m-rt's `link.x`, for bare-metal targets only (host builds and tests
//! of the library never see a linker script).

use std::path::PathBuf;

fn main() {
    println!("cargo:rerun-if-changed=../memory.x");
    println!("cargo:rerun-if-changed=build.rs");
    if std::env::var("CARGO_CFG_TARGET_OS").as_deref() != Ok("none") {
        return;
    }
    let out = PathBuf::from(std::env::var("OUT_DIR").expect("cargo sets OUT_DIR"));
    std::fs::copy("../memory.x", out.join("memory.x")).expect("copy memory.x");
    println!("cargo:rustc-link-search={}", out.display());
    println!("cargo:rustc-link-arg-bins=-Tlink.x");
    // defmt's log strings live in an ELF section its linker script describes.
    if std::env::var_os("CARGO_FEATURE_BOARD_DEBUG").is_some() {
        println!("cargo:rustc-link-arg-bins=-Tdefmt.x");
    }
}
