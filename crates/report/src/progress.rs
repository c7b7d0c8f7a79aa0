//! Progress bars on stderr (hidden when stderr is not a terminal), so stdout stays the report;
//! each step also polls Ctrl-C, so a long loop stops at the step it is in.

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use specmux_core::{interrupt, Result};
use std::borrow::Cow;

/// A bar with a message, position, length, elapsed and remaining time; set its length later.
pub fn bar(message: impl Into<Cow<'static, str>>) -> ProgressBar {
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

/// One step done: advance the bar, then stop with `Error::Interrupted` naming `during` if
/// Ctrl-C was pressed.
pub fn step(bar: &ProgressBar, during: &str) -> Result<()> {
    bar.inc(1);
    interrupt::check(during)
}
