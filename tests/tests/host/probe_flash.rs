//! The documented probe procedure against the firmware's one rule for which
//! model runs (firmware::model_store): the commands README.md,
//! docs/firmware.md and docs/workflow.md give for flashing a model with a
//! debug probe are replayed, as probe-rs performs them (the whole 128 KiB
//! sector erased, commit record included, then the bytes written), on a
//! unit whose slots already hold UART-installed, committed models; the model
//! the probe flashed must be the one that boots.

use firmware::model_store::ModelStore;
use firmware_harness::fault_injection::{EMULATED_LAYOUT, ModelFlash};
use rbf_core::blob::{self, MAX_BLOB_LEN};

/// The model slots' addresses on the chip (memory.x: MODEL_A, MODEL_B).
const SLOT_ADDRESSES: [u32; 2] = [0x080C_0000, 0x080E_0000];

/// The base addresses of the `probe-rs download` lines of `text` (a line
/// may name the same download again at a second address).
fn probe_downloads(text: &str) -> Vec<u32> {
    text.lines()
        .filter(|line| line.contains("probe-rs download"))
        .flat_map(|line| {
            let words: Vec<&str> = line.split_whitespace().collect();
            words
                .windows(2)
                .filter(|w| w[0].trim_start_matches('`') == "--base-address")
                .filter_map(|w| {
                    let hex = w[1].strip_prefix("0x")?;
                    let digits = hex.find(|c: char| !c.is_ascii_hexdigit()).unwrap_or(hex.len());
                    u32::from_str_radix(&hex[..digits], 16).ok()
                })
                .collect::<Vec<_>>()
        })
        .collect()
}

/// `blob` flashed as probe-rs does it at `address`: the slot's sector
/// erased whole, then the blob written at its start.
fn probe_download(flash: &mut ModelFlash, address: u32, blob: &[u8]) {
    let slot = SLOT_ADDRESSES
        .iter()
        .position(|&a| a == address)
        .unwrap_or_else(|| panic!("the procedure writes {address:#010x}, not a model slot"));
    let start = EMULATED_LAYOUT.offsets[slot] as usize;
    let contents = flash.contents_mut();
    contents[start..start + EMULATED_LAYOUT.len as usize].fill(0xFF);
    contents[start..start + blob.len()].copy_from_slice(blob);
}

fn encode(model: &rbf_core::Model) -> Vec<u8> {
    let mut buf = vec![0u8; MAX_BLOB_LEN];
    let n = blob::encode(model, &mut buf).unwrap();
    buf.truncate(n);
    buf
}

#[test]
fn a_model_flashed_by_the_documented_probe_procedure_runs_over_earlier_uart_installs() {
    let dir = tempfile::tempdir().unwrap();
    let (fitted, _) = e2e_tests::fixtures::model_and_faulty_slice(dir.path());
    let installed = encode(&fitted);
    let probed_model = e2e_tests::fixtures::cubic_model();
    let probed = encode(&probed_model);
    let root = concat!(env!("CARGO_MANIFEST_DIR"), "/..");
    for doc in ["README.md", "docs/firmware.md", "docs/workflow.md"] {
        let text = std::fs::read_to_string(format!("{root}/{doc}")).unwrap();
        let downloads = probe_downloads(&text);
        assert!(!downloads.is_empty(), "{doc} documents the probe procedure");
        // A unit in service: two UART installs, slot B committed last.
        let mut store = ModelStore::open(ModelFlash::new(), EMULATED_LAYOUT);
        store.install(&installed).unwrap();
        store.install(&installed).unwrap();
        let mut flash = store.into_flash();
        for address in downloads {
            probe_download(&mut flash, address, &probed);
        }
        let mut store = ModelStore::open(flash, EMULATED_LAYOUT);
        assert_eq!(
            store.load().ok(),
            Some(probed_model.clone()),
            "{doc}: after its probe procedure the unit runs the probed model, not the committed one"
        );
    }
}
