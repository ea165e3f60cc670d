//! Progress of long commands on stderr: on a terminal, a bar per stage with its rate and the
//! time left (indicatif); where stderr is a file or a pipe, a plain line a second. Warnings
//! and notices are printed as lines either way.

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use solver::{Progress, ProgressLine, ProgressThrottle};
use std::io::IsTerminal;
use std::sync::Mutex;
use std::time::{Duration, Instant};

/// Shows a long computation's [`Progress`] to the person who started it.
pub(crate) struct ProgressPrinter {
    start: Instant,
    throttle: ProgressThrottle,
    /// On a terminal: the bar, and the stage it shows now.
    bar: Option<(ProgressBar, Mutex<Option<Stage>>)>,
}

/// What the bar shows: a count out of a known total, or a count with no total.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Stage {
    FormFactors,
    Probes,
    Gathering,
    Solve,
    Refine,
}

impl Stage {
    fn of(progress: &Progress) -> Option<Stage> {
        match progress {
            Progress::FormFactors { .. } => Some(Stage::FormFactors),
            Progress::Probes { .. } => Some(Stage::Probes),
            Progress::Gathering { .. } => Some(Stage::Gathering),
            Progress::Solve { .. } => Some(Stage::Solve),
            Progress::Refining { .. } => Some(Stage::Refine),
            _ => None,
        }
    }

    fn name(self) -> &'static str {
        match self {
            Stage::FormFactors => "form factors",
            Stage::Probes => "probes",
            Stage::Gathering => "vertex light",
            Stage::Solve => "solve",
            Stage::Refine => "refine",
        }
    }

    fn style(self) -> ProgressStyle {
        let template = match self {
            Stage::FormFactors | Stage::Probes => {
                "{prefix:>12} {elapsed_precise} {wide_bar} {percent:>3}% {per_sec} ({eta} left)"
            }
            Stage::Gathering => {
                "{prefix:>12} {elapsed_precise} {wide_bar} {percent:>3}% {msg} ({eta} left)"
            }
            Stage::Solve | Stage::Refine => "{prefix:>12} {elapsed_precise} {spinner} {msg}",
        };
        ProgressStyle::with_template(template).expect("a valid template")
    }
}

impl ProgressPrinter {
    /// A printer that draws bars when stderr is a terminal.
    pub(crate) fn new() -> Self {
        let bar = std::io::stderr().is_terminal().then(|| {
            let bar = ProgressBar::with_draw_target(None, ProgressDrawTarget::stderr());
            (bar, Mutex::new(None))
        });
        ProgressPrinter {
            start: Instant::now(),
            throttle: ProgressThrottle::new(Duration::from_secs(1)),
            bar,
        }
    }

    /// Shows `progress`: on the bar when there is one and it is a stage's count, else as a line.
    pub(crate) fn report(&self, progress: Progress) {
        if let (Some((bar, shown)), Some(stage)) = (&self.bar, Stage::of(&progress)) {
            let mut shown = shown.lock().expect("progress lock");
            if *shown != Some(stage) {
                bar.set_style(stage.style());
                bar.reset();
                bar.set_prefix(stage.name());
                *shown = Some(stage);
            }
            draw(bar, &progress);
            return;
        }
        let line = match self.throttle.admit(progress) {
            Some(ProgressLine::Warning(line)) => format!("warning: {line}"),
            Some(ProgressLine::Notice(line)) => line,
            Some(ProgressLine::Status(line)) => {
                format!("[{:6.1}s] {line}", self.start.elapsed().as_secs_f64())
            }
            None => return,
        };
        match &self.bar {
            Some((bar, _)) => bar.suspend(|| eprintln!("{line}")),
            None => eprintln!("{line}"),
        }
    }
}

/// Moves the bar to where `progress` says the stage is: a count out of its total, or the
/// stage's own line beside a spinner.
fn draw(bar: &ProgressBar, progress: &Progress) {
    match *progress {
        Progress::FormFactors { done, total } | Progress::Probes { done, total, .. } => {
            bar.set_length(total as u64);
            bar.set_position(done as u64);
        }
        Progress::Gathering { pass, done, total } => {
            bar.set_message(pass.to_string());
            bar.set_length(total as u64);
            bar.set_position(done as u64);
        }
        _ => {
            bar.set_message(progress.describe().unwrap_or_default());
            bar.tick();
        }
    }
}

impl Drop for ProgressPrinter {
    fn drop(&mut self) {
        if let Some((bar, _)) = &self.bar {
            bar.finish_and_clear();
        }
    }
}
