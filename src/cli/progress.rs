//! The progress bar on a terminal, fed by the library's progress callback.

use indicatif::{ProgressBar, ProgressStyle};
use rovib::Progress;

/// A bar on stderr (none when `show` is false), with `unit` after the counts; [`Bar::update`]
/// is the library's progress callback.
pub struct Bar {
    bar: Option<ProgressBar>,
    failures: bool,
}

impl Bar {
    /// A bar of `unit`s (`outputs`, `trajectories`); with `failures`, the failed count beside it.
    pub fn new(show: bool, unit: &str, failures: bool) -> Self {
        let bar = show.then(|| {
            let bar = ProgressBar::new(0);
            let msg = if failures { ", {msg}" } else { "" };
            let template =
                format!("{{spinner}} [{{elapsed_precise}}] {{wide_bar}} {{pos}}/{{len}} {unit}{msg}, eta {{eta}}");
            bar.set_style(ProgressStyle::with_template(&template).unwrap_or_else(|_| ProgressStyle::default_bar()));
            bar
        });
        Self { bar, failures }
    }

    /// Shows `p`.
    pub fn update(&mut self, p: Progress) {
        if let Some(bar) = &self.bar {
            bar.set_length(p.total);
            bar.set_position(p.done);
            if self.failures {
                bar.set_message(format!("{} failed", p.failed));
            }
        }
    }
}

impl Drop for Bar {
    fn drop(&mut self) {
        if let Some(bar) = &self.bar {
            bar.finish_and_clear();
        }
    }
}
