//! `radcast fuzz`: a seeded mutation fuzzer that runs on the stable toolchain, over the scene
//! loader and everything a loaded scene goes through ([`scene`]), and over every wire decoder
//! and the viewer's buffer ([`wire`]). A finding is a panic, a case that runs past
//! [`HANG_LIMIT`], or a wrong outcome the target names (non-finite radiosity, an error that
//! does not say where); each is saved as files that reproduce it.

pub mod mutate;
pub mod scene;
pub mod wire;

use anyhow::Context;
use mutate::Choices;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// A case's input: named files (a scene and its MTL, or one message).
pub type Input = Vec<(String, Vec<u8>)>;

/// What a case came to, when nothing went wrong.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Outcome {
    /// The input was valid and its result checked.
    Accepted,
    /// The input was refused with a proper error.
    Rejected,
}

/// Something the fuzzer can aim at.
pub trait Target: Sync {
    /// Its name on the command line.
    fn name(&self) -> &'static str;
    /// Case input, from the stream of choices of that case.
    fn input(&self, choices: &mut Choices) -> Input;
    /// Runs one case in `scratch` (an empty folder); `Err` names a wrong outcome.
    fn run(&self, input: &Input, scratch: &Path) -> Result<Outcome, String>;
}

/// A case taking longer than this counts as a hang.
pub const HANG_LIMIT: Duration = Duration::from_secs(30);

/// When to stop.
#[derive(Clone, Copy, Debug)]
pub struct Budget {
    /// Stop after this many cases.
    pub cases: Option<u64>,
    /// Stop after this long.
    pub time: Option<Duration>,
}

/// One finding, saved under the crash folder.
#[derive(Clone, Debug)]
pub struct Finding {
    /// The case number (with the seed, it regenerates the input).
    pub case: u64,
    /// The panic message or the wrong outcome.
    pub what: String,
    /// Where its input was saved.
    pub saved: PathBuf,
}

/// What a run did.
#[derive(Debug)]
pub struct Report {
    /// Cases run.
    pub cases: u64,
    /// Cases whose input was valid.
    pub accepted: u64,
    /// Cases refused with a proper error.
    pub rejected: u64,
    /// Panics, hangs and wrong outcomes.
    pub findings: Vec<Finding>,
    /// Wall time of the run.
    pub seconds: f64,
    /// The slowest case and its seconds.
    pub slowest: (u64, f64),
}

/// Saves `input` as the files of case `case` under `dir`.
fn save(dir: &Path, target: &str, seed: u64, case: u64, input: &Input) -> anyhow::Result<PathBuf> {
    let folder = dir.join(format!("{target}-seed{seed}-case{case}"));
    std::fs::create_dir_all(&folder)
        .with_context(|| format!("{}: cannot create", folder.display()))?;
    for (name, bytes) in input {
        std::fs::write(folder.join(name), bytes)
            .with_context(|| format!("{}: cannot write", folder.join(name).display()))?;
    }
    Ok(folder)
}

/// The text of a caught panic.
fn panic_text(payload: &(dyn std::any::Any + Send)) -> String {
    payload
        .downcast_ref::<&str>()
        .map(|s| s.to_string())
        .or_else(|| payload.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "a panic with no message".into())
}

/// Runs cases 0, 1, ... of `seed` against `target` until the budget is spent, saving every
/// finding under `crash_dir`. A hang ends the process (exit code 2) once its input is saved.
pub fn run(
    target: &dyn Target,
    seed: u64,
    budget: Budget,
    crash_dir: &Path,
) -> anyhow::Result<Report> {
    let scratch = tempfile::tempdir().context("no scratch folder")?;
    let started = Instant::now();
    let current: Arc<Mutex<Option<(u64, Instant, Input)>>> = Arc::default();
    {
        let (current, crash_dir, name) = (current.clone(), crash_dir.to_path_buf(), target.name());
        std::thread::spawn(move || {
            loop {
                std::thread::sleep(Duration::from_secs(1));
                let guard = current.lock().unwrap_or_else(|e| e.into_inner());
                if let Some((case, since, input)) = guard.as_ref()
                    && since.elapsed() > HANG_LIMIT
                {
                    let saved = save(&crash_dir, name, seed, *case, input);
                    eprintln!("hang: {name} case {case} ran past {HANG_LIMIT:?}; input: {saved:?}");
                    std::process::exit(2);
                }
            }
        });
    }
    // Panics are findings, reported once each below, not printed as they happen.
    let quiet = std::panic::take_hook();
    std::panic::set_hook(Box::new(|_| {}));
    let mut report = Report {
        cases: 0,
        accepted: 0,
        rejected: 0,
        findings: Vec::new(),
        seconds: 0.0,
        slowest: (0, 0.0),
    };
    for case in 0.. {
        let spent = budget.cases.is_some_and(|n| case >= n)
            || budget.time.is_some_and(|t| started.elapsed() >= t);
        if spent {
            break;
        }
        let input = target.input(&mut Choices::new(seed, case));
        let case_dir = scratch.path().join("case");
        let _ = std::fs::remove_dir_all(&case_dir);
        std::fs::create_dir_all(&case_dir).context("scratch folder")?;
        let case_started = Instant::now();
        *current.lock().unwrap_or_else(|e| e.into_inner()) =
            Some((case, case_started, input.clone()));
        let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            target.run(&input, &case_dir)
        }));
        *current.lock().unwrap_or_else(|e| e.into_inner()) = None;
        let seconds = case_started.elapsed().as_secs_f64();
        if seconds > report.slowest.1 {
            report.slowest = (case, seconds);
        }
        report.cases += 1;
        let what = match result {
            Ok(Ok(Outcome::Accepted)) => {
                report.accepted += 1;
                continue;
            }
            Ok(Ok(Outcome::Rejected)) => {
                report.rejected += 1;
                continue;
            }
            Ok(Err(wrong)) => wrong,
            Err(panic) => format!("panic: {}", panic_text(panic.as_ref())),
        };
        let saved = save(crash_dir, target.name(), seed, case, &input)?;
        report.findings.push(Finding { case, what, saved });
    }
    std::panic::set_hook(quiet);
    report.seconds = started.elapsed().as_secs_f64();
    Ok(report)
}
/// The arguments of `radcast fuzz`.
#[derive(clap::Args)]
pub struct FuzzCommand {
    /// What to fuzz.
    #[arg(value_enum)]
    pub target: FuzzTarget,
    /// Stop after this many cases.
    #[arg(long)]
    pub cases: Option<u64>,
    /// Stop after this many seconds (with --cases: whichever comes first).
    #[arg(long)]
    pub seconds: Option<f64>,
    /// Seed: the same seed and case number give the same input.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Where findings' inputs are saved.
    #[arg(long, default_value = "fuzz-findings")]
    pub findings: PathBuf,
    /// Folders of scene files to mutate (`scene` target).
    #[arg(long, default_values = ["scenes", "tests/fuzz/scenes"])]
    pub corpus: Vec<PathBuf>,
}

/// What `radcast fuzz` aims at.
#[derive(Clone, Copy, Debug, clap::ValueEnum)]
pub enum FuzzTarget {
    /// OBJ and MTL files through the loader, meshing and a small solve.
    Scene,
    /// Every wire decoder and the viewer's colour buffer.
    Wire,
}

impl FuzzCommand {
    /// Runs the command.
    pub fn run(self) -> anyhow::Result<()> {
        let FuzzCommand {
            target,
            cases,
            seconds,
            seed,
            findings,
            corpus,
        } = self;
        anyhow::ensure!(
            cases.is_some() || seconds.is_some(),
            "give --cases N, --seconds T or both"
        );
        let time = seconds
            .map(|s| Duration::try_from_secs_f64(s).context("--seconds must be >= 0"))
            .transpose()?;
        let target: Box<dyn Target> = match target {
            FuzzTarget::Scene => Box::new(scene::SceneTarget::from_folders(
                &corpus.iter().map(PathBuf::as_path).collect::<Vec<_>>(),
            )?),
            FuzzTarget::Wire => Box::new(wire::WireTarget::default()),
        };
        let budget = Budget { cases, time };
        let report = run(target.as_ref(), seed, budget, &findings)?;
        println!(
            "{}: {} cases in {:.1} s (seed {seed}): {} accepted, {} rejected with an error, {} findings; slowest case {} took {:.3} s",
            target.name(),
            report.cases,
            report.seconds,
            report.accepted,
            report.rejected,
            report.findings.len(),
            report.slowest.0,
            report.slowest.1
        );
        for finding in &report.findings {
            println!(
                "  case {}: {} (input in {})",
                finding.case,
                finding.what,
                finding.saved.display()
            );
        }
        if !report.findings.is_empty() {
            std::process::exit(1);
        }
        Ok(())
    }
}
