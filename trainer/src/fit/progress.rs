//! The fit's progress bar.

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

/// A progress bar that is silent when disabled or not on a terminal.
pub struct Progress {
    bar: ProgressBar,
}

/// Every stage's bar: its name, the bar, the count and the time left.
fn style() -> ProgressStyle {
    ProgressStyle::with_template("{msg:>20} [{bar:30}] {pos}/{len} ({eta})")
        .unwrap_or_else(|_| ProgressStyle::default_bar())
        .progress_chars("=> ")
}

impl Progress {
    /// A bar, hidden unless `visible`.
    pub fn new(visible: bool) -> Self {
        Progress::on(if visible {
            ProgressDrawTarget::stderr()
        } else {
            ProgressDrawTarget::hidden()
        })
    }

    /// A bar drawn on `target`, styled from the start: indicatif draws on
    /// the first change, so a bar styled after it would show once unnamed.
    fn on(target: ProgressDrawTarget) -> Self {
        Progress {
            bar: ProgressBar::with_draw_target(Some(0), target).with_style(style()),
        }
    }

    /// Starts a stage of `total` steps: named before its length is set,
    /// since setting the length draws the bar.
    pub fn start(&self, stage: &str, total: u64) {
        self.bar.set_message(stage.to_owned());
        self.bar.set_length(total);
        self.bar.set_position(0);
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

#[cfg(test)]
mod tests {
    use std::sync::{Arc, Mutex};

    use super::*;

    /// A terminal that keeps what is written on it.
    #[derive(Debug, Clone, Default)]
    struct Screen(Arc<Mutex<Vec<String>>>);

    impl indicatif::TermLike for Screen {
        fn width(&self) -> u16 {
            100
        }
        fn move_cursor_up(&self, _: usize) -> std::io::Result<()> {
            Ok(())
        }
        fn move_cursor_down(&self, _: usize) -> std::io::Result<()> {
            Ok(())
        }
        fn move_cursor_right(&self, _: usize) -> std::io::Result<()> {
            Ok(())
        }
        fn move_cursor_left(&self, _: usize) -> std::io::Result<()> {
            Ok(())
        }
        fn write_line(&self, s: &str) -> std::io::Result<()> {
            self.write_str(s)
        }
        fn write_str(&self, s: &str) -> std::io::Result<()> {
            if !s.trim().is_empty() {
                self.0.lock().unwrap().push(s.to_owned());
            }
            Ok(())
        }
        fn clear_line(&self) -> std::io::Result<()> {
            Ok(())
        }
        fn flush(&self) -> std::io::Result<()> {
            Ok(())
        }
    }

    #[test]
    fn every_bar_drawn_names_its_stage() {
        let screen = Screen::default();
        let progress = Progress::on(ProgressDrawTarget::term_like(Box::new(screen.clone())));
        progress.start("lag-bank structure", 3);
        progress.inc();
        progress.finish();
        let drawn = screen.0.lock().unwrap().clone();
        assert!(!drawn.is_empty(), "nothing drawn");
        for line in &drawn {
            assert!(
                line.contains("lag-bank structure"),
                "a bar without its stage: {line:?} in {drawn:?}"
            );
        }
    }
}
