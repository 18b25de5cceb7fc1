//! A terminal progress bar behind the library's `Progress` trait.

use indicatif::{ProgressBar, ProgressStyle};

/// Shows a bar on stderr (hidden when quiet or when stderr is not a terminal).
pub struct Bar(ProgressBar);

impl Bar {
    /// A bar labelled `what`.
    pub fn new(what: &str, quiet: bool) -> Self {
        let bar = if quiet {
            ProgressBar::hidden()
        } else {
            ProgressBar::new(0)
        };
        bar.set_style(
            ProgressStyle::with_template(
                "{msg:>10} [{bar:40}] {percent:>3}% {elapsed} (eta {eta})",
            )
            .unwrap()
            .progress_chars("=> "),
        );
        bar.set_message(what.to_string());
        Bar(bar)
    }

    /// Clears the bar.
    pub fn finish(&self) {
        self.0.finish_and_clear();
    }
}

impl drbokeh::Progress for Bar {
    fn start(&self, total: u64) {
        self.0.set_length(total);
        self.0.set_position(0);
    }
    fn advance(&self, units: u64) {
        self.0.inc(units);
    }
}
