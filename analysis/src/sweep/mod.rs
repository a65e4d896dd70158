//! `formation sweep`: Monte Carlo or grid over scenario parameters, each sample run by the
//! in-process runner ([`formation_runtime::sim::run_in_process_with`]) on `--jobs` threads.
//!
//! * [`spec`]: `--vary NAME=SPEC` and the sampling.
//! * [`apply`]: what each parameter does to the base scenario.
//! * [`report`]: one CSV row per sample (`DIR/sweep.csv`) and the summary (`DIR/sweep.json`).
//!
//! Every sample writes `DIR/samples/NNNN/{scenario.toml,summary.json}` (no trajectory), so any
//! sample can be flown again with `formation sim DIR/samples/NNNN/scenario.toml`.

pub mod apply;
pub mod report;
pub mod spec;

use formation_runtime::cli;
use report::{Outcome, Progress, SampleError};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::mpsc;
use std::time::Instant;

/// Arguments of `formation sweep`.
#[derive(clap::Args, Debug)]
pub struct SweepArgs {
    /// Base scenario, variant, output directory (default out/sweep-<scenario>), overrides.
    #[command(flatten)]
    pub common: cli::RunnerArgs,
    /// A parameter and its values: NAME=LO..HI, NAME=LO..HI/COUNT, NAME=V1,V2,... (repeatable).
    /// Names: n, graph, k, seed, delay.max, fault.gamma, fault.delta, start_offset, target_speed,
    /// or any scenario path as for --set. See docs/sweep.md.
    #[arg(long = "vary", value_name = "NAME=SPEC")]
    pub vary: Vec<String>,
    /// Monte Carlo: number of samples.
    #[arg(long, default_value_t = 100)]
    pub samples: usize,
    /// Monte Carlo: seed of the sampling (sample k depends only on the seed and k).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Grid instead of Monte Carlo: every combination of the (finite) value sets.
    #[arg(long)]
    pub grid: bool,
    /// Samples run at once (threads). Default: the CPUs this process may use.
    #[arg(long)]
    pub jobs: Option<usize>,
}

/// Why a sweep cannot run or produced nothing: the option, file or folder and what failed.
#[derive(Debug, thiserror::Error)]
pub enum SweepError {
    /// The base scenario does not load or is invalid: why, then that the base is refused.
    #[error("{0}\nerror: invalid base scenario")]
    Base(cli::InputError),
    /// A `--vary` is malformed, or a `--grid` set is not finite.
    #[error(transparent)]
    Spec(#[from] spec::SpecError),
    /// A parameter varied twice.
    #[error("--vary {0}: given twice")]
    Twice(String),
    /// `--samples 0`.
    #[error("--samples 0: expected at least 1")]
    NoSamples,
    /// The output folder is refused (the folder check's message: it reports its errors as text).
    #[error("cannot use {}: {why}", out.display())]
    Folder {
        /// The output folder.
        out: PathBuf,
        /// Why.
        why: String,
    },
    /// `sweep.csv` or `sweep.json` cannot be written.
    #[error("cannot write {}/{file}: {source}", out.display())]
    Write {
        /// The output folder.
        out: PathBuf,
        /// `sweep.csv` or `sweep.json`.
        file: &'static str,
        /// What the system said.
        source: std::io::Error,
    },
    /// No sample's scenario was valid.
    #[error("every sample's scenario was invalid (sweep.csv, column error); the first: {first}")]
    AllInvalid {
        /// The first sample's error, `-` if none.
        first: String,
    },
}

/// Entry point of `formation sweep`: runs the samples and writes `sweep.csv` and `sweep.json`.
pub fn main(args: SweepArgs) -> Result<(), SweepError> {
    run(&args)
}

fn run(args: &SweepArgs) -> Result<(), SweepError> {
    let (base, variant) = args.common.load().map_err(SweepError::Base)?;
    let vary = args
        .vary
        .iter()
        .map(|v| spec::parse(v, apply::is_integer))
        .collect::<Result<Vec<_>, _>>()?;
    for (i, v) in vary.iter().enumerate() {
        if vary[..i].iter().any(|w| w.name == v.name) {
            return Err(SweepError::Twice(v.name.clone()));
        }
    }
    let samples = if args.grid {
        spec::grid(&vary)?
    } else {
        if args.samples == 0 {
            return Err(SweepError::NoSamples);
        }
        spec::monte_carlo(&vary, args.samples, args.seed)
    };
    let jobs = args
        .jobs
        .unwrap_or_else(|| formation_runtime::cpus::allowed().len().max(1))
        .clamp(1, samples.len().max(1));
    let out = args
        .common
        .out
        .clone()
        .unwrap_or_else(|| PathBuf::from(format!("out/sweep-{}", base.name)));
    formation_runtime::out_lock::check_folder(&out)
        .map_err(|e| e.to_string())
        .and_then(|()| {
            formation_config::node::files::ensure_private_dir(&out.join("samples"))
                .map_err(|e| e.to_string())
        })
        .map_err(|why| SweepError::Folder {
            out: out.clone(),
            why,
        })?;
    eprintln!(
        "sweep: {} samples ({}), {jobs} jobs, writing {}",
        samples.len(),
        if args.grid { "grid" } else { "Monte Carlo" },
        out.display()
    );
    let start = Instant::now();
    let outcomes = run_samples(&base, variant, &samples, jobs, &out);
    let wall = start.elapsed().as_secs_f64();
    let names: Vec<String> = vary.iter().map(|v| v.name.clone()).collect();
    let write_error = |file| {
        let out = out.clone();
        move |source| SweepError::Write { out, file, source }
    };
    report::write_csv(&out.join("sweep.csv"), &names, &outcomes)
        .map_err(write_error("sweep.csv"))?;
    let summary = report::SweepSummary::build(
        &outcomes,
        report::Setup {
            mode: if args.grid { "grid" } else { "monte-carlo" },
            seed: args.seed,
            jobs,
            vary: args.vary.clone(),
            base: base.name.clone(),
            variant: variant.name().to_string(),
            wall_time_s: wall,
        },
    );
    summary
        .write(&out.join("sweep.json"))
        .map_err(write_error("sweep.json"))?;
    summary.print();
    println!("wrote {}/sweep.csv and sweep.json", out.display());
    if summary.invalid == outcomes.len() {
        return Err(SweepError::AllInvalid {
            first: summary.first_error.as_deref().unwrap_or("-").to_string(),
        });
    }
    Ok(())
}

/// Runs every sample on `jobs` threads; outcomes in sample order.
fn run_samples(
    base: &formation_config::Scenario,
    variant: formation_config::Variant,
    samples: &[spec::Sample],
    jobs: usize,
    out: &Path,
) -> Vec<Outcome> {
    let next = AtomicUsize::new(0);
    let (tx, rx) = mpsc::channel::<Outcome>();
    let mut outcomes: Vec<Option<Outcome>> = vec![None; samples.len()];
    std::thread::scope(|scope| {
        for _ in 0..jobs {
            let tx = tx.clone();
            let next = &next;
            scope.spawn(move || loop {
                let k = next.fetch_add(1, Ordering::Relaxed);
                let Some(sample) = samples.get(k) else {
                    break;
                };
                let dir = out.join("samples").join(format!("{:04}", sample.index));
                let outcome = run_one(base, variant, sample, &dir);
                if tx.send(outcome).is_err() {
                    break;
                }
            });
        }
        drop(tx);
        let mut progress = Progress::new(samples.len());
        for o in rx {
            progress.done(&o);
            let k = o.sample.index;
            outcomes[k] = Some(o);
        }
        progress.finish();
    });
    outcomes.into_iter().flatten().collect()
}

/// One sample: build its scenario, fly it, keep what the report needs.
fn run_one(
    base: &formation_config::Scenario,
    variant: formation_config::Variant,
    sample: &spec::Sample,
    dir: &Path,
) -> Outcome {
    let start = Instant::now();
    let write_error = |e| SampleError::Write {
        dir: dir.to_path_buf(),
        source: std::sync::Arc::new(e),
    };
    let result = apply::apply(base, &sample.values)
        .map_err(SampleError::Apply)
        .and_then(|s| {
            formation_runtime::sim::write_resolved_scenario(&s, dir).map_err(write_error)?;
            formation_runtime::sim::run_in_process_with(
                &s,
                variant,
                dir,
                formation_runtime::record::Outputs {
                    trajectory: false,
                    ..formation_runtime::record::Outputs::with(&[])
                },
            )
            .map_err(write_error)
        });
    Outcome::new(sample.clone(), result, start.elapsed().as_secs_f64())
}
