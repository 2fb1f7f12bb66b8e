//! Opening what a command reads: `-` is standard input, and every input is
//! read once, front to back, so pipes and FIFOs work; small inputs (model
//! blobs, parameter files) are read through a size limit.

use std::fs::File;
use std::io::Read;
use std::os::unix::fs::MetadataExt;
use std::path::Path;

use crate::text;

/// True for `-`, the name of standard input.
pub fn is_stdin(path: &Path) -> bool {
    path.as_os_str() == text::STDIN_PATH
}

/// Opens `path` for reading (`-`: standard input).
pub fn open(path: &Path) -> std::io::Result<Box<dyn Read + Send>> {
    if is_stdin(path) {
        Ok(Box::new(std::io::stdin()))
    } else {
        Ok(Box::new(File::open(path)?))
    }
}

/// Reads all of `path`, refusing it past `limit` bytes (`what` names what
/// the file should be, for the message); reads at most `limit + 1` bytes,
/// so an endless source (`/dev/zero`) is refused at once.
pub fn read_limited(path: &Path, limit: u64, what: &str) -> anyhow::Result<Vec<u8>> {
    let mut bytes = Vec::new();
    open(path)
        .and_then(|source| source.take(limit + 1).read_to_end(&mut bytes))
        .map_err(|e| anyhow::anyhow!("{}: cannot read: {e}", text::path(path)))?;
    if bytes.len() as u64 > limit {
        anyhow::bail!(
            "{}: more than {limit} bytes; {what} is at most {} (the limit)",
            text::path(path),
            crate::reading::limits::bytes(limit)
        );
    }
    Ok(bytes)
}

/// Refuses `-` given more than once among `paths`: standard input can be read only once.
pub fn check_stdin_once<'a>(paths: impl IntoIterator<Item = &'a Path>) -> anyhow::Result<()> {
    if paths.into_iter().filter(|p| is_stdin(p)).count() > 1 {
        anyhow::bail!("- (standard input) is given more than once; it can be read only once");
    }
    Ok(())
}

/// Refuses inputs that cannot be read twice, for commands that need several
/// passes (`command` names the command and why, for the message).
pub fn require_seekable<'a>(paths: impl IntoIterator<Item = &'a Path>, command: &str) -> anyhow::Result<()> {
    for path in paths {
        if !is_stdin(path) && std::fs::metadata(path).is_ok_and(|m| m.is_dir()) {
            anyhow::bail!(
                "{}: is a directory, not a recorded run; name the run files in it",
                text::path(path)
            );
        }
        let regular = !is_stdin(path) && std::fs::metadata(path).is_ok_and(|m| m.is_file());
        let exists = is_stdin(path) || std::fs::metadata(path).is_ok();
        if exists && !regular {
            anyhow::bail!(
                "{}: {command} and needs a seekable file, not standard input, a pipe or a device; save the data to a file first",
                text::path(path)
            );
        }
    }
    Ok(())
}

/// The file an input path names (device, inode), following links; standard
/// input's own file for `-`. `None` when it cannot be found.
pub fn identity(path: &Path) -> Option<(u64, u64)> {
    let target = if is_stdin(path) { Path::new("/dev/stdin") } else { path };
    std::fs::metadata(target).ok().map(|m| (m.dev(), m.ino()))
}
