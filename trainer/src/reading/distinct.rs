//! Is every run of a command a different run? A run listed twice (the same
//! file, a byte copy, or the same rows with other `#` lines or line ends)
//! counts twice in a fit, or passes for an independent check of itself:
//! the commands refuse it by content, whatever its name.

use std::path::{Path, PathBuf};

use crate::text;

/// The runs of one role on a command line: its name as messages say it
/// (`training`, `--validate`, `--holdout`, `evaluated`) and its paths.
pub type Role<'a> = (&'a str, &'a [PathBuf]);

/// Refuses a run that holds the same data as a run listed before it, in its
/// own role or an earlier one of `roles` (listed from the runs that weigh
/// most, the training runs, to those only reported), naming both runs, how
/// they are the same (the same file, a copy, or the same rows once `#` lines,
/// blank lines and `\r` line ends are left out) and what listing it twice would do.
/// Standard input (`-`) is never compared: it is read once and not kept.
pub fn require_distinct_runs(roles: &[Role]) -> anyhow::Result<()> {
    let mut seen: Vec<(&str, &Path, Option<Digests>)> = Vec::new();
    for &(role, paths) in roles {
        for path in paths {
            if crate::reading::input::is_stdin(path) {
                continue;
            }
            let digests = Digests::of(path)?;
            for (earlier_role, earlier, earlier_digests) in &seen {
                if let Some(how) = same_data((earlier, earlier_digests.as_ref()), (path, digests.as_ref())) {
                    anyhow::bail!(
                        "{}: the {role} run is {how} {earlier_role} run {}: {}",
                        text::path(path),
                        text::path(earlier),
                        consequence(role, earlier_role)
                    );
                }
            }
            seen.push((role, path, digests));
        }
    }
    Ok(())
}

/// What listing a `role` run that an `earlier_role` run already holds would do.
fn consequence(role: &str, earlier_role: &str) -> String {
    match (earlier_role, role) {
        ("training", "training") => "it would count twice and pull the model towards it; list each run once".into(),
        ("training", _) => format!(
            "its figures would be the training run's, not an independent check; drop it from {role}, or record another \
             run to hold out"
        ),
        (a, b) if a == b => "its figures would count twice as if from two runs; list each run once".into(),
        _ => format!(
            "the {earlier_role} run already chose or judged the model, so its figures would be no independent check; \
             drop it from {role}, or record another run"
        ),
    }
}

/// How the files at `a` and `b` (with their [`Digests`], `None` for what is
/// not a regular file) hold the same data: `the same file as`, `a copy of`,
/// `the same rows as` (equal once `#` lines, blank lines and `\r` line ends
/// are left out, so a copy with its metadata stripped or its line ends
/// converted is still found), or `None`.
fn same_data(a: (&Path, Option<&Digests>), b: (&Path, Option<&Digests>)) -> Option<&'static str> {
    if let (Ok(ca), Ok(cb)) = (a.0.canonicalize(), b.0.canonicalize())
        && ca == cb
    {
        return Some("the same file as");
    }
    let (da, db) = (a.1?, b.1?);
    if da.rows != db.rows || da.rows_digest != db.rows_digest {
        return None;
    }
    Some(if da.bytes == db.bytes && da.raw_digest == db.raw_digest {
        "a copy of"
    } else {
        "the same rows as"
    })
}

/// Digests of a file's data rows and of its bytes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Digests {
    /// Over the lines that are neither `#` lines nor blank, without their line ends.
    rows_digest: u64,
    /// Lines the row digest took.
    rows: u64,
    /// Over every byte.
    raw_digest: u64,
    /// The file's length, bytes.
    bytes: u64,
}

impl Digests {
    /// The [`Digests`] of the file at `path`, streamed; `None` for what is
    /// not a regular file (a pipe is read once, by the command).
    fn of(path: &Path) -> anyhow::Result<Option<Digests>> {
        use std::hash::Hasher;
        use std::io::BufRead;
        let named = |e: std::io::Error| anyhow::anyhow!("{}: {e}", text::path(path));
        match std::fs::metadata(path) {
            Ok(m) if m.is_file() => {}
            _ => return Ok(None),
        }
        let mut reader = std::io::BufReader::with_capacity(1 << 20, std::fs::File::open(path).map_err(named)?);
        let (mut rows_digest, mut raw_digest) = (std::hash::DefaultHasher::new(), std::hash::DefaultHasher::new());
        let (mut rows, mut bytes) = (0u64, 0u64);
        let mut line = Vec::new();
        loop {
            line.clear();
            if reader.read_until(b'\n', &mut line).map_err(named)? == 0 {
                break;
            }
            raw_digest.write(&line);
            bytes += line.len() as u64;
            let mut row = line.as_slice();
            while let [head @ .., b'\n' | b'\r'] = row {
                row = head;
            }
            if row.is_empty() || row.starts_with(b"#") {
                continue;
            }
            rows_digest.write(row);
            rows_digest.write_u8(b'\n');
            rows += 1;
        }
        Ok(Some(Digests {
            rows_digest: rows_digest.finish(),
            rows,
            raw_digest: raw_digest.finish(),
            bytes,
        }))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn file(dir: &tempfile::TempDir, name: &str, text: &str) -> PathBuf {
        let p = dir.path().join(name);
        std::fs::write(&p, text).unwrap();
        p
    }

    #[test]
    fn a_run_in_two_roles_or_twice_in_one_is_refused_by_its_rows() {
        let dir = tempfile::TempDir::new().unwrap();
        let a = file(&dir, "a.csv", "# x: 1\ntime_s,rate_dph\n0,1\n1,2\n");
        let b = file(&dir, "b.csv", "time_s,rate_dph\n0,1\n1,3\n");
        let crlf = file(&dir, "c.csv", "time_s,rate_dph\r\n0,1\r\n1,3\r\n");
        let copy = file(&dir, "d.csv", "time_s,rate_dph\n0,1\n1,3\n");
        let ok = [a.clone()];
        let (validate, holdout) = ([b.clone()], [crlf.clone()]);
        let e = require_distinct_runs(&[("training", &ok), ("--validate", &validate), ("--holdout", &holdout)])
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("c.csv: the --holdout run is the same rows as --validate run") && e.contains("b.csv"),
            "{e}"
        );
        let twice = [b.clone(), copy.clone()];
        let e = require_distinct_runs(&[("evaluated", &twice)]).unwrap_err().to_string();
        assert!(e.contains("the evaluated run is a copy of evaluated run"), "{e}");
        assert!(require_distinct_runs(&[("training", &[a, b])]).is_ok());
    }
}
