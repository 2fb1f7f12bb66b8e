//! The flag that turns a refusal into acceptance, named after the message:
//! one list for every command line that calls the library (`trainer`'s
//! subcommands and `cargo xtask qemu-replay`), so they say the same.

/// What a command line adds to a library error: the flag that changes the
/// outcome (`; pass --force to overwrite it`), or nothing.
pub fn flag_hint(e: &anyhow::Error) -> &'static str {
    let root = e.root_cause();
    if root.is::<crate::output::OutputExists>() {
        "; pass --force to overwrite it"
    } else if root.is::<crate::output::OutputReadOnly>() {
        ", even with --force"
    } else if root.is::<crate::evaluation::evaluate::NothingCompensated>() {
        ". Pass --allow-uncompensated to accept such a run"
    } else if root.is::<crate::reading::plausible::Implausible>() {
        ". Convert the run to the recorded-run format's units, or pass --allow-implausible if it is right"
    } else {
        ""
    }
}
