//! Host files over semihosting (the QEMU images only): a file read line by
//! line and a file written, in the directory QEMU runs in. Without
//! `-semihosting-config enable=on` the first call hangs the guest: QEMU runs
//! under a timeout (xtask).
#![allow(unsafe_code)]
// The callers only need to know that a write failed or a line is unusable.
#![allow(clippy::result_unit_err)]

use cortex_m_semihosting::{nr, syscall};

/// Longest input line, bytes.
pub const LINE_CAPACITY: usize = 1024;
/// Input read chunk, bytes.
pub const CHUNK: usize = 4096;

/// Reads a host file line by line over semihosting.
pub struct HostLines {
    fd: usize,
    chunk: [u8; CHUNK],
    start: usize,
    end: usize,
    eof: bool,
    line: heapless::Vec<u8, LINE_CAPACITY>,
}

/// Opens a host file; `path_nul` ends with a NUL byte.
pub fn host_open(path_nul: &str, mode: usize) -> Option<usize> {
    // SAFETY: SYS_OPEN reads the NUL-terminated name and returns a handle or -1.
    let fd = unsafe { syscall!(OPEN, path_nul.as_ptr(), mode, path_nul.len() - 1) };
    (fd as isize != -1).then_some(fd)
}

/// Closes a handle [`host_open`] gave.
pub fn host_close(fd: usize) {
    // SAFETY: closes a handle we opened.
    unsafe { syscall!(CLOSE, fd) };
}

/// A host file written over semihosting.
pub struct HostFile(usize);

impl HostFile {
    /// Creates (or truncates) the host file `path_nul` (NUL-terminated).
    pub fn create(path_nul: &str) -> Option<Self> {
        host_open(path_nul, nr::open::W_TRUNC_BINARY).map(HostFile)
    }

    /// Writes all of `buf`.
    pub fn write_all(&mut self, mut buf: &[u8]) -> Result<(), ()> {
        while !buf.is_empty() {
            // SAFETY: SYS_WRITE reads buf.len() bytes from buf; returns the count NOT written.
            let not_written = unsafe { syscall!(WRITE, self.0, buf.as_ptr(), buf.len()) };
            if not_written >= buf.len() {
                return Err(());
            }
            buf = &buf[buf.len() - not_written..];
        }
        Ok(())
    }
}

impl Drop for HostFile {
    fn drop(&mut self) {
        host_close(self.0);
    }
}

impl HostLines {
    /// Opens the host file `path_nul` (NUL-terminated) for reading.
    pub fn open(path_nul: &str) -> Option<Self> {
        host_open(path_nul, nr::open::R_BINARY).map(|fd| HostLines {
            fd,
            chunk: [0; CHUNK],
            start: 0,
            end: 0,
            eof: false,
            line: heapless::Vec::new(),
        })
    }

    fn fill(&mut self) {
        // SAFETY: SYS_READ writes at most CHUNK bytes into our buffer and returns the count NOT read.
        let not_read = unsafe { syscall!(READ, self.fd, self.chunk.as_mut_ptr(), CHUNK) };
        self.start = 0;
        self.end = CHUNK.saturating_sub(not_read);
        self.eof = self.end == 0;
    }

    /// The next line without its `\n`; `Err(())` for a line over capacity or non-UTF-8.
    pub fn next_line(&mut self) -> Option<Result<&str, ()>> {
        self.line.clear();
        let mut overflow = false;
        loop {
            if self.start == self.end {
                if self.eof {
                    break;
                }
                self.fill();
                if self.eof {
                    break;
                }
            }
            let b = self.chunk[self.start];
            self.start += 1;
            if b == b'\n' {
                return Some(if overflow {
                    Err(())
                } else {
                    core::str::from_utf8(&self.line).map_err(|_| ())
                });
            }
            overflow |= self.line.push(b).is_err();
        }
        if self.line.is_empty() {
            None
        } else {
            Some(if overflow {
                Err(())
            } else {
                core::str::from_utf8(&self.line).map_err(|_| ())
            })
        }
    }
}

impl Drop for HostLines {
    fn drop(&mut self) {
        host_close(self.fd);
    }
}
