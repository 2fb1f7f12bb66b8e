//! Opening the unit's serial port, with errors that name it and say what to do.

use std::time::Duration;

use serialport::{ErrorKind, SerialPort};

use crate::text;

/// The board's UART rate (docs/firmware.md): 921,600 Bd, 8N1.
pub const DEFAULT_BAUD: u32 = 921_600;

/// How long one read waits for bytes before the caller checks its deadline.
pub const READ_SLICE: Duration = Duration::from_millis(50);

/// Opens `port` at `baud` (8N1, no flow control, exclusive), raw.
pub fn open(port: &str, baud: u32) -> anyhow::Result<Box<dyn SerialPort>> {
    serialport::new(port, baud)
        .timeout(READ_SLICE)
        .open()
        .map_err(|e| anyhow::anyhow!("{}", describe_open_error(port, &e)))
}

/// What an open error means for `port`, in words.
pub fn describe_open_error(port: &str, e: &serialport::Error) -> String {
    let shown = text::terminal_safe(port);
    match e.kind() {
        ErrorKind::Io(std::io::ErrorKind::NotFound) => {
            format!("{shown}: no such port (is the unit's serial adapter plugged in? `ls /dev/tty*` lists the ports)")
        }
        ErrorKind::Io(std::io::ErrorKind::PermissionDenied) => format!(
            "{shown}: permission denied (on Linux, add yourself to the group that owns it, often `dialout`, and log in again)"
        ),
        ErrorKind::NoDevice => format!("{shown}: busy: another program has the port open ({})", e.description),
        _ => format!("{shown}: cannot open the port: {}", e.description),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_missing_port_is_named_and_explained() {
        let err = open("/dev/no-such-port-36", DEFAULT_BAUD).unwrap_err().to_string();
        assert!(err.starts_with("/dev/no-such-port-36: no such port"), "{err}");
        let busy = serialport::Error::new(ErrorKind::NoDevice, "Device or resource busy");
        assert!(describe_open_error("/dev/ttyUSB0", &busy).contains("/dev/ttyUSB0: busy"));
        let denied = serialport::Error::new(ErrorKind::Io(std::io::ErrorKind::PermissionDenied), "x");
        assert!(describe_open_error("/dev/ttyUSB0", &denied).contains("permission denied"));
    }

    #[test]
    fn a_file_that_is_no_terminal_is_refused_with_its_name() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("plain.txt");
        std::fs::write(&file, "x").unwrap();
        let err = open(file.to_str().unwrap(), DEFAULT_BAUD).unwrap_err().to_string();
        assert!(err.starts_with(&format!("{}: ", file.display())), "{err}");
    }
}
