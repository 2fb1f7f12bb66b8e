//! The fit's progress bar.

use indicatif::{ProgressBar, ProgressStyle};

/// A progress bar that is silent when disabled or not on a terminal.
pub struct Progress {
    bar: ProgressBar,
}

impl Progress {
    /// A bar, hidden unless `visible`.
    pub fn new(visible: bool) -> Self {
        Progress {
            bar: if visible {
                ProgressBar::new(0)
            } else {
                ProgressBar::hidden()
            },
        }
    }

    /// Starts a stage of `total` steps.
    pub fn start(&self, stage: &str, total: u64) {
        self.bar.set_length(total);
        self.bar.set_position(0);
        self.bar.set_style(
            ProgressStyle::with_template("{msg:>20} [{bar:30}] {pos}/{len} ({eta})")
                .unwrap_or_else(|_| ProgressStyle::default_bar())
                .progress_chars("=> "),
        );
        self.bar.set_message(stage.to_owned());
    }

    /// One step done.
    pub fn inc(&self) {
        self.bar.inc(1);
    }

    /// The stage is over.
    pub fn finish(&self) {
        self.bar.finish_and_clear();
    }
}
