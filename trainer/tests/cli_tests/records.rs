//! Calibration records against real databases (SQLite files, a PostgreSQL server the test
//! starts): a batch records every unit, `trainer history` returns them with the blob's
//! CRC, nothing is lost when two batches write one store at once or a batch is killed,
//! and a store that cannot take the records (damaged, newer, read-only, unreachable) fails
//! the batch before any fit, left as it was.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use crate::common::postgres::PostgresServer;
use crate::common::{inspect_json, short_chamber_run, stderr, stdout, trainer};
use tempfile::TempDir;

/// A single `trainer fit` of unit FOG-1 (the first run of batch directory
/// `runs`, written beside it) with `--records store` exits 1 naming `needle`
/// and writes no model (`what`: the case, for the messages).
fn single_fit_refuses(runs: &Path, store: &str, needle: &str, what: &str) {
    let model = runs.with_file_name("single.bin");
    let train = runs.join("u1.csv");
    let o = trainer(&[
        "fit",
        train.to_str().unwrap(),
        "--serial",
        "FOG-1",
        "-o",
        model.to_str().unwrap(),
        "--records",
        store,
    ]);
    assert_eq!(o.status.code(), Some(1), "fit, {what}: {}", stderr(&o));
    assert!(stderr(&o).contains(needle), "fit, {what}: {}", stderr(&o));
    assert!(!model.exists(), "fit, {what}: no model written");
}

/// A batch directory: `n` units FOG-1 … FOG-n (a training and a holdout run each, seeds
/// from `seed`), an optional broken unit FOG-X (its training run cut short), a spec any fit
/// passes; returns the manifest.
fn batch_dir(dir: &Path, name: &str, n: usize, seed: usize, broken: bool) -> PathBuf {
    let runs = dir.join(format!("runs-{name}"));
    std::fs::create_dir_all(&runs).unwrap();
    let mut manifest = format!("batch = \"{name}\"\nspec = \"spec.toml\"\n");
    for i in 1..=n {
        let (train, holdout) = (runs.join(format!("u{i}.csv")), runs.join(format!("h{i}.csv")));
        short_chamber_run(&train, &(seed + i).to_string());
        short_chamber_run(&holdout, &(seed + 100 + i).to_string());
        manifest += &format!(
            "[[unit]]\nserial = \"FOG-{i}\"\ntrain = [\"runs-{name}/u{i}.csv\"]\nholdout = [\"runs-{name}/h{i}.csv\"]\n"
        );
    }
    if broken {
        let whole = std::fs::read(runs.join("u1.csv")).unwrap();
        std::fs::write(runs.join("broken.csv"), &whole[..2000]).unwrap();
        manifest += &format!("[[unit]]\nserial = \"FOG-X\"\ntrain = [\"runs-{name}/broken.csv\"]\n");
    }
    std::fs::write(dir.join("spec.toml"), "[holdout]\nstd100_gain_min_pct = 1\n").unwrap();
    let path = dir.join(format!("{name}.toml"));
    std::fs::write(&path, manifest).unwrap();
    path
}

fn batch(manifest: &Path, out: &Path, store: &str, extra: &[&str]) -> std::process::Output {
    let args = [
        "batch",
        manifest.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
        "--records",
        store,
    ];
    trainer(&[&args[..], extra].concat())
}

/// `trainer history … --records STORE --json`, parsed.
fn history(which: &[&str], store: &str) -> Vec<serde_json::Value> {
    let o = trainer(&[&["history"][..], which, &["--records", store, "--json"]].concat());
    assert!(o.status.success(), "history {which:?}: {}", stderr(&o));
    serde_json::from_str(&stdout(&o)).unwrap()
}

/// `trainer inspect --model MODEL --format json`'s `crc32`.
fn inspected_crc(model: &Path) -> String {
    inspect_json(model)["crc32"].as_str().unwrap().to_owned()
}

/// Every record of a batch is whole: a passing unit's blob is the model its CRC names.
fn assert_whole(records: &[serde_json::Value]) {
    for r in records {
        assert!(
            ["pass", "fail", "error"].contains(&r["status"].as_str().unwrap()),
            "{r}"
        );
        assert!(r["fitted_utc"].as_str().unwrap().ends_with('Z'), "{r}");
        if r["status"] == "pass" {
            assert_eq!(r["blob_check"], "ok", "{r}");
            assert!(r["figures"]["holdout_std100_after_dph"].is_number(), "{r}");
        }
    }
}

/// The batch of two good units and a broken one into `store`: a record per unit, each
/// passing one with the CRC `inspect` prints, its runs' digests and figures; the broken
/// one an error naming its file; `history --batch` lists all three; a later `fit
/// --records` of a unit comes first in its history.
fn a_batch_records_every_unit(store: &str) {
    let dir = TempDir::new().unwrap();
    let manifest = batch_dir(dir.path(), "B-R", 2, 0, true);
    let out = dir.path().join("out");
    let o = batch(&manifest, &out, store, &[]);
    assert_eq!(o.status.code(), Some(3), "{}", stderr(&o));
    for serial in ["FOG-1", "FOG-2"] {
        let records = history(&[serial], store);
        assert_eq!(records.len(), 1, "{records:?}");
        let r = &records[0];
        let model = out.join(serial).join("model.bin");
        assert_eq!((r["serial"].as_str(), r["batch"].as_str()), (Some(serial), Some("B-R")));
        assert_eq!(
            (r["axis"].as_str(), r["status"].as_str()),
            (Some("single"), Some("pass"))
        );
        assert_eq!(
            r["model_crc32"].as_str().unwrap(),
            inspected_crc(&model),
            "the blob's CRC"
        );
        assert_eq!(r["model_crc32"].as_str().unwrap().len(), 10, "0x and eight hex digits");
        assert_eq!(r["blob_bytes"], std::fs::metadata(&model).unwrap().len());
        assert_eq!(r["model_id"].as_str().unwrap().len(), 8);
        let train = dir.path().join("runs-B-R").join(format!("u{}.csv", &serial[4..]));
        assert_eq!(
            r["training_runs"][0]["sha256"],
            ::trainer::provenance::sha256_file(&train).unwrap().as_str()
        );
        let summary: serde_json::Value =
            serde_json::from_slice(&std::fs::read(out.join("summary.json")).unwrap()).unwrap();
        let row = summary["units"]
            .as_array()
            .unwrap()
            .iter()
            .find(|u| u["serial"] == serial)
            .unwrap();
        assert_eq!(&r["figures"], row, "the record holds the summary row");
    }
    let broken = history(&["FOG-X"], store);
    assert_eq!(broken[0]["status"], "error");
    assert!(
        broken[0]["reasons"][0].as_str().unwrap().contains("broken.csv:"),
        "{}",
        broken[0]
    );
    assert!(broken[0]["model_crc32"].is_null());
    let all = history(&["--batch", "B-R"], store);
    assert_eq!(all.len(), 3);
    assert_whole(&all);
    // A later single fit of FOG-1: first in its history, newest first.
    let refit = dir.path().join("refit.bin");
    let train = dir.path().join("runs-B-R").join("u1.csv");
    let o = trainer(&[
        "fit",
        "-q",
        train.to_str().unwrap(),
        "--serial",
        "FOG-1",
        "-o",
        refit.to_str().unwrap(),
        "--records",
        store,
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let records = history(&["FOG-1"], store);
    assert_eq!(records.len(), 2);
    assert_eq!(records[0]["model_crc32"].as_str().unwrap(), inspected_crc(&refit));
    assert!(records[0]["batch"].is_null() && records[1]["batch"] == "B-R");
    let table = stdout(&trainer(&["history", "FOG-1", "--records", store]));
    assert_eq!(table.lines().count(), 3, "a header and a line per record: {table}");
}

#[test]
fn a_batch_records_every_unit_in_a_sqlite_file() {
    let dir = TempDir::new().unwrap();
    let store = dir.path().join("cal.sqlite");
    a_batch_records_every_unit(store.to_str().unwrap());
}

#[test]
fn a_batch_records_every_unit_in_postgresql() {
    let Some(server) = PostgresServer::start_or_skip("a_batch_records_every_unit_in_postgresql") else {
        return;
    };
    a_batch_records_every_unit(&server.url());
}

/// A PostgreSQL store of a newer schema than this trainer knows: `fit`, `batch` and
/// `history` refuse it by name, and no table of it is touched (its rows stay as they were).
#[test]
fn a_postgresql_store_of_a_newer_schema_is_refused_and_left_unchanged() {
    let Some(server) =
        PostgresServer::start_or_skip("a_postgresql_store_of_a_newer_schema_is_refused_and_left_unchanged")
    else {
        return;
    };
    let url = server.url();
    drop(::trainer::records::Store::open(&url, ::trainer::records::Access::Write).unwrap());
    let mut client = postgres::Client::connect(&url, postgres::NoTls).unwrap();
    client
        .execute(
            "INSERT INTO schema_version (version, applied_utc) VALUES (99, '2030-01-01T00:00:00Z')",
            &[],
        )
        .unwrap();
    let snapshot = |client: &mut postgres::Client| -> Vec<String> {
        let mut rows: Vec<String> = client
            .query("SELECT version::text || ' ' || applied_utc FROM schema_version", &[])
            .unwrap()
            .iter()
            .map(|r| r.get::<_, String>(0))
            .collect();
        rows.sort();
        rows
    };
    let before = snapshot(&mut client);

    let dir = TempDir::new().unwrap();
    let manifest = batch_dir(dir.path(), "B-N", 1, 40, false);
    let out = dir.path().join("out");
    let needle = "schema is version 99, newer than this trainer knows";
    let o = batch(&manifest, &out, &url, &[]);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert!(stderr(&o).contains(needle), "{}", stderr(&o));
    assert!(!out.exists(), "no fit ran");
    single_fit_refuses(&dir.path().join("runs-B-N"), &url, needle, "newer schema");
    let o = trainer(&["history", "FOG-1", "--records", &url]);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert!(stderr(&o).contains(needle), "{}", stderr(&o));
    assert_eq!(snapshot(&mut client), before, "the store is left as it was");
}

/// Two batches writing one SQLite file at the same time: every record of both is there.
#[test]
fn two_batches_writing_one_sqlite_store_at_once_lose_no_record() {
    let dir = TempDir::new().unwrap();
    let store = dir.path().join("cal.sqlite");
    let store = store.to_str().unwrap();
    let spawn = |name: &str, seed: usize| {
        let manifest = batch_dir(dir.path(), name, 2, seed, false);
        Command::new(env!("CARGO_BIN_EXE_trainer"))
            .args(["batch", manifest.to_str().unwrap(), "-o"])
            .arg(dir.path().join(format!("out-{name}")))
            .args(["--records", store, "--jobs", "2"])
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap()
    };
    let (a, b) = (spawn("B-A", 10), spawn("B-B", 20));
    for child in [a, b] {
        let o = child.wait_with_output().unwrap();
        assert!(o.status.success(), "{}", stderr(&o));
    }
    for name in ["B-A", "B-B"] {
        let records = history(&["--batch", name], store);
        assert_eq!(records.len(), 2, "{name}: {records:?}");
        assert_whole(&records);
    }
}

/// A store that cannot take the records fails the batch before any fit (exit 1, no
/// OUTDIR) and is left exactly as it was.
#[test]
fn a_store_that_cannot_take_records_fails_the_batch_before_any_fit_and_is_left_unchanged() {
    let dir = TempDir::new().unwrap();
    let manifest = batch_dir(dir.path(), "B-S", 1, 30, false);
    let out = dir.path().join("out");
    // A store of this trainer's schema, to damage, lock and move ahead.
    let good = dir.path().join("good.sqlite");
    drop(::trainer::records::Store::open(good.to_str().unwrap(), ::trainer::records::Access::Write).unwrap());

    let not_a_database = dir.path().join("notes.sqlite");
    std::fs::write(&not_a_database, "serial,crc\nFOG-1,0x1234\n".repeat(300)).unwrap();
    let damaged = dir.path().join("damaged.sqlite");
    let mut bytes = std::fs::read(&good).unwrap();
    let len = bytes.len();
    assert!(len >= 8192, "a store of several pages");
    bytes[len - 4096..].fill(0xA5);
    std::fs::write(&damaged, &bytes).unwrap();
    let newer = dir.path().join("newer.sqlite");
    std::fs::copy(&good, &newer).unwrap();
    rusqlite::Connection::open(&newer)
        .unwrap()
        .execute(
            "INSERT INTO schema_version (version, applied_utc) VALUES (99, '2030-01-01T00:00:00Z')",
            [],
        )
        .unwrap();
    let read_only = dir.path().join("read-only.sqlite");
    std::fs::copy(&good, &read_only).unwrap();
    let mut permissions = std::fs::metadata(&read_only).unwrap().permissions();
    permissions.set_readonly(true);
    std::fs::set_permissions(&read_only, permissions).unwrap();

    let cases: [(&str, String, &str); 5] = [
        (
            "not a database",
            not_a_database.display().to_string(),
            "not a SQLite database",
        ),
        ("damaged", damaged.display().to_string(), "damaged"),
        (
            "newer schema",
            newer.display().to_string(),
            "schema is version 99, newer than this trainer knows",
        ),
        ("read-only", read_only.display().to_string(), "read-only"),
        (
            "unreachable server",
            "postgres://nobody@127.0.0.1:1/records".to_owned(),
            "cannot connect",
        ),
    ];
    for (what, store, needle) in cases {
        let before = std::fs::read(&store).ok();
        let o = batch(&manifest, &out, &store, &[]);
        assert_eq!(o.status.code(), Some(1), "{what}: {}", stderr(&o));
        assert!(
            stderr(&o).contains(needle) && stderr(&o).contains("records store"),
            "{what}: {}",
            stderr(&o)
        );
        assert!(!out.exists(), "{what}: no fit ran, nothing written");
        assert_eq!(
            std::fs::read(&store).ok(),
            before,
            "{what}: the store is left as it was"
        );
        // A single fit refuses the store the same way, before it fits.
        single_fit_refuses(&dir.path().join("runs-B-S"), &store, needle, what);
        if what == "newer schema" {
            let o = trainer(&["history", "FOG-1", "--records", &store]);
            assert_eq!(o.status.code(), Some(1), "history refuses it too");
        }
    }
}

/// A batch killed with SIGKILL (its whole process group, the fits too) after its first
/// record: the store opens, every record in it is whole, and `--resume` completes the
/// batch with one record per unit (the kept units' records not written twice).
#[test]
fn a_batch_killed_midway_leaves_whole_records_and_resume_completes_them() {
    let dir = TempDir::new().unwrap();
    let manifest = batch_dir(dir.path(), "B-K", 3, 40, false);
    let out = dir.path().join("out");
    let store = dir.path().join("cal.sqlite");
    let store = store.to_str().unwrap();
    let mut child = {
        use std::os::unix::process::CommandExt;
        Command::new(env!("CARGO_BIN_EXE_trainer"))
            .args(["batch", manifest.to_str().unwrap(), "-o", out.to_str().unwrap()])
            .args(["--records", store, "--jobs", "1"])
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .process_group(0)
            .spawn()
            .unwrap()
    };
    let started = Instant::now();
    let recorded = || {
        let o = trainer(&["history", "--batch", "B-K", "--records", store, "--json"]);
        serde_json::from_str::<Vec<serde_json::Value>>(&stdout(&o)).map_or(0, |v| v.len())
    };
    while recorded() == 0 {
        assert!(started.elapsed() < Duration::from_secs(600), "no record within 10 min");
        assert!(
            child.try_wait().unwrap().is_none(),
            "the batch ended before it was killed"
        );
        std::thread::sleep(Duration::from_millis(100));
    }
    let killed = Command::new("kill")
        .args(["-KILL", "--", &format!("-{}", child.id())])
        .status()
        .unwrap();
    assert!(killed.success());
    child.wait().unwrap();
    let integrity: String = rusqlite::Connection::open(store)
        .unwrap()
        .query_row("PRAGMA integrity_check", [], |r| r.get(0))
        .unwrap();
    assert_eq!(integrity, "ok");
    let before = history(&["--batch", "B-K"], store);
    assert!(!before.is_empty() && before.len() < 3, "{before:?}");
    assert_whole(&before);
    let o = batch(&manifest, &out, store, &["--resume"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let after = history(&["--batch", "B-K"], store);
    assert_whole(&after);
    let mut serials: Vec<&str> = after.iter().map(|r| r["serial"].as_str().unwrap()).collect();
    serials.sort_unstable();
    assert_eq!(serials, ["FOG-1", "FOG-2", "FOG-3"], "one record per unit");
}
