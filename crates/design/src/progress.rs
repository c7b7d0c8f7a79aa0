//! Progress bars on stderr (hidden when stderr is not a terminal), so stdout stays the report.

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};

/// A bar with a message, position, length, elapsed and remaining time; set its length later.
pub fn bar(message: &'static str) -> ProgressBar {
    let b = ProgressBar::with_draw_target(Some(0), ProgressDrawTarget::stderr());
    let style = ProgressStyle::with_template(
        "{msg:32} [{bar:40}] {pos}/{len} {elapsed_precise} (eta {eta})",
    )
    .unwrap_or_else(|_| ProgressStyle::default_bar())
    .progress_chars("=> ");
    b.set_style(style);
    b.set_message(message);
    b
}
