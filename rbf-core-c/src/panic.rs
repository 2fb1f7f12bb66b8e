//! The panic handler of the bare-metal library. No panic is reachable from
//! the exported functions; with the `panic-free-check` feature the handler
//! calls a symbol defined nowhere, so a C program linked with every export
//! kept fails to link if one were (xtask's c-library check, docs/panic-free.md).

#[cfg(feature = "panic-free-check")]
unsafe extern "C" {
    /// Defined nowhere: a reference to it that survives the link is a panic path.
    fn hot_path_can_panic() -> !;
}

#[panic_handler]
fn panic(_: &core::panic::PanicInfo<'_>) -> ! {
    #[cfg(feature = "panic-free-check")]
    // SAFETY: never defined, never called: linking fails first.
    unsafe {
        hot_path_can_panic()
    }
    #[cfg(not(feature = "panic-free-check"))]
    loop {
        core::hint::spin_loop();
    }
}
