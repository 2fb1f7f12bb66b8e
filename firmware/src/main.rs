//! Board binary: wiring only. On the host it is an empty program so that
//! `cargo build --workspace` and clippy work; on the target it boots with
//! cortex-m-rt and validates the model slot.
#![cfg_attr(target_os = "none", no_std, no_main)]

#[cfg(target_os = "none")]
mod board {
    use core::panic::PanicInfo;
    use cortex_m_rt::entry;

    #[allow(unsafe_code)]
    unsafe extern "C" {
        static _model_a_start: u8;
    }

    /// The MODEL_A flash slot (memory.x) as bytes.
    #[allow(unsafe_code)]
    fn model_slot() -> &'static [u8] {
        // SAFETY: memory.x reserves MODEL_SLOT_LEN bytes of read-only flash at
        // `_model_a_start`; nothing in the program image writes there.
        unsafe { core::slice::from_raw_parts(&raw const _model_a_start, firmware::MODEL_SLOT_LEN) }
    }

    #[entry]
    fn main() -> ! {
        let model = firmware::load_model(model_slot()).ok();
        // Skeleton: the compensation loop arrives with the firmware issue.
        core::hint::black_box(&model);
        loop {
            cortex_m::asm::wfi();
        }
    }

    #[panic_handler]
    fn panic(_: &PanicInfo) -> ! {
        cortex_m::asm::udf()
    }
}

#[cfg(not(target_os = "none"))]
fn main() {
    eprintln!("the firmware runs on thumbv7em-none-eabihf: build it with `cargo fw-build`");
}
