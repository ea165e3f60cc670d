//! One module per command; what they share.

pub mod load;
pub mod view;
pub mod watch;

use anyhow::Context;
use std::time::Duration;

/// `value` seconds as a duration, or an error naming `--flag`.
pub fn positive_seconds(value: f64, flag: &str) -> anyhow::Result<Duration> {
    Duration::try_from_secs_f64(value)
        .with_context(|| format!("--{flag} must be a non-negative number of seconds, got {value}"))
}
