//! Links the QEMU images as firmware's own images are: cortex-m-rt's
//! `link.x` over the workspace `memory.x`, which firmware's build script
//! (firmware/build.rs) puts on the linker path of every crate that
//! depends on it. Bare-metal targets only.

fn main() {
    println!("cargo:rerun-if-changed=build.rs");
    if std::env::var("CARGO_CFG_TARGET_OS").as_deref() == Ok("none") {
        println!("cargo:rustc-link-arg-bins=-Tlink.x");
    }
}
