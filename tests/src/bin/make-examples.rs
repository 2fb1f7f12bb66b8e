//! Writes the bundled example chamber runs into `examples/data/`.
//!
//! `cargo run -p e2e-tests --bin make-examples` (the files are committed; the
//! generator is deterministic, so this reproduces them byte for byte).

use std::path::Path;

use e2e_tests::chamber::ChamberRun;

fn main() -> anyhow::Result<()> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples/data");
    std::fs::create_dir_all(&dir)?;
    let runs = [
        ("chamber_train_1cpm.csv", ChamberRun::ifog(1.0, 1)),
        ("chamber_verify_0p5cpm.csv", ChamberRun::ifog(0.5, 2)),
        ("chamber_verify_2cpm.csv", ChamberRun::ifog(2.0, 3)),
    ];
    for (name, run) in runs {
        std::fs::write(dir.join(name), run.to_csv())?;
        println!("wrote examples/data/{name}");
    }
    Ok(())
}
