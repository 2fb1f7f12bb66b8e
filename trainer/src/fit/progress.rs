//! The fit's progress bar.

use std::sync::{Mutex, PoisonError};

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

/// Where a stage's bar is drawn: made anew for each stage's bar.
type DrawTarget = Box<dyn Fn() -> ProgressDrawTarget + Send + Sync>;

/// A progress bar that is silent when disabled or not on a terminal.
pub struct Progress {
    target: DrawTarget,
    /// The current stage's bar.
    bar: Mutex<ProgressBar>,
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
        Progress::on(Box::new(move || {
            if visible {
                ProgressDrawTarget::stderr()
            } else {
                ProgressDrawTarget::hidden()
            }
        }))
    }

    /// Bars drawn on what `target` makes.
    fn on(target: DrawTarget) -> Self {
        Progress {
            target,
            bar: Mutex::new(ProgressBar::hidden()),
        }
    }

    /// Starts a stage of `total` steps: a new bar, named, styled and of its
    /// length before it first draws (indicatif draws on every change, so a
    /// bar set up step by step shows once unnamed or of no length).
    pub fn start(&self, stage: &str, total: u64) {
        let bar = ProgressBar::with_draw_target(Some(total), (self.target)())
            .with_style(style())
            .with_message(stage.to_owned());
        bar.tick();
        *self.bar.lock().unwrap_or_else(PoisonError::into_inner) = bar;
    }

    /// One step done.
    pub fn inc(&self) {
        self.current().inc(1);
    }

    /// The stage is over.
    pub fn finish(&self) {
        self.current().finish_and_clear();
    }

    /// The current stage's bar (a handle: cloning shares it).
    fn current(&self) -> ProgressBar {
        self.bar.lock().unwrap_or_else(PoisonError::into_inner).clone()
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
    fn every_bar_drawn_names_its_stage_and_counts_to_its_length() {
        let screen = Screen::default();
        let on_screen = screen.clone();
        let progress = Progress::on(Box::new(move || {
            ProgressDrawTarget::term_like(Box::new(on_screen.clone()))
        }));
        for (stage, total) in [("lag-bank structure", 3), ("selecting centres", 5)] {
            progress.start(stage, total);
            progress.inc();
            progress.finish();
        }
        let drawn = screen.0.lock().unwrap().clone();
        for (stage, total) in [("lag-bank structure", 3), ("selecting centres", 5)] {
            assert!(
                drawn.iter().any(|l| l.contains(stage)),
                "{stage} never drawn: {drawn:?}"
            );
            for line in drawn.iter().filter(|l| l.contains(stage)) {
                assert!(
                    line.contains(&format!("/{total} ")),
                    "a bar of {stage} without its length: {line:?} in {drawn:?}"
                );
            }
        }
        assert!(
            drawn
                .iter()
                .all(|l| l.contains("lag-bank structure") || l.contains("selecting centres")),
            "a bar without its stage: {drawn:?}"
        );
    }
}
