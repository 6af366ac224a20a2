use super::{Failure, Outcome};
use calib_analysis::diagnosis::outside::{found_outside_the_library, Found};
use calib_analysis::diagnosis::{self, report};
use calib_engine::campaign::Campaign;
use calib_engine::evaluator::LocalEvaluator;
use calib_engine::optim::problem::Progress;
use calib_engine::store::SledStore;
use calib_service::dispatch::RemoteWorkers;
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct Args {
    /// Campaign file (TOML), as for `calib calibrate`, optionally with a [diagnosis] section
    /// (holdout_start, holdout_stop, refit, candidates).
    campaign: PathBuf,
    /// Results folder: diagnosis.json, diagnosis.md and the plots go to
    /// DIR/<campaign name>/diagnosis/ [default: results/ beside the campaign file].
    #[arg(long)]
    out: Option<PathBuf>,
    /// Print diagnosis.json to standard output instead of the summary.
    #[arg(long)]
    json: bool,
    /// Spread the calibrations and the simulations of the diagnosis over workers.
    #[command(flatten)]
    workers: super::WorkersArgs,
    /// Evaluation store (a folder, created when absent), shared with `calib calibrate`:
    /// every evaluated point is kept there, so a repeated or interrupted diagnosis simulates
    /// only the points it lacks [default: results/.calib-db beside the campaign file].
    #[arg(long, value_name = "DIR")]
    db: Option<PathBuf>,
    /// Also profile the likelihood of each selected effect around the final fit (as `calib
    /// profile` does, with the fit's noise level): its 95% interval beside the linearised one.
    #[arg(long)]
    profile: bool,
    /// After the diagnosis, look outside the effect library (furuta only): estimate the
    /// torque the final fit still misses on each joint from the record, find the few
    /// functions of the angles, speeds and inputs it is made of (sparse regression), print
    /// the formula with each term's 95% interval and the `[[effects]]` block to paste, and
    /// refit the campaign with it (its objective against the noise floor). Runs whatever
    /// the verdict; the proposal is never written into the campaign file. Goes into
    /// diagnosis.json (`found_outside_the_library`) and diagnosis.md. See docs/discovery.md.
    #[arg(long)]
    discover: bool,
}

/// A spinner counting evaluations, drawn only on a terminal.
struct Spinner(ProgressBar);

impl Progress for Spinner {
    fn evaluated(&self, count: usize, _best_objective: f64) {
        self.0.inc(count as u64);
    }
}

pub fn run(args: Args) -> Outcome {
    let campaign = Campaign::load(&args.campaign).map_err(|e| Failure::input(e.to_string()))?;
    let db = args
        .db
        .clone()
        .unwrap_or_else(|| super::calibrate::default_db(&args.campaign));
    let store = SledStore::open(&db).map_err(|e| Failure::internal(e.to_string()))?;
    let workers = match &args.workers.workers {
        Some(list) => Some(args.workers.connect(list)?),
        None => None,
    };
    let (d, found) = diagnose(&args, &campaign, &store, workers.as_ref())?;
    // `--out` is a results root, as for `calib calibrate`: one `<name>/` per campaign.
    let out = super::calibrate::results_root(&args.campaign, args.out.as_deref())
        .join(&campaign.name)
        .join("diagnosis");
    let written = report::write(&d, &out)?;
    let mut json = report::diagnosis_json(&d);
    if let Some(found) = &found {
        json["found_outside_the_library"] = found.json();
        add_to_outputs(&out, &json, found)?;
    }
    if args.json {
        println!(
            "{}",
            serde_json::to_string_pretty(&json).expect("plain data")
        );
        return Ok(());
    }
    print_fit(&d);
    print_profiles_and_verdict(&d, args.profile, found.as_ref());
    println!(
        "{} evaluations, {} simulated, {} from the store ({}); {} trajectories simulated; {:.2} s",
        d.stats.evaluations.requested,
        d.stats.evaluations.simulated,
        d.stats.evaluations.cached,
        db.display(),
        d.stats.trajectories,
        d.elapsed.as_secs_f64()
    );
    for path in written {
        println!("wrote {}", path.display());
    }
    Ok(())
}

/// The diagnosis (with the profiles of the selected effects and discovery when asked for),
/// a spinner on the terminal while it runs.
fn diagnose(
    args: &Args,
    campaign: &Campaign,
    store: &SledStore,
    workers: Option<&RemoteWorkers>,
) -> Result<(diagnosis::Diagnosis, Option<Found>), Failure> {
    let bar = ProgressBar::with_draw_target(None, ProgressDrawTarget::stderr());
    bar.set_style(
        ProgressStyle::with_template("{spinner} {elapsed_precise} {pos} evaluations {msg}")
            .expect("valid template"),
    );
    bar.set_message("calibrating, ranking candidate effects, refitting");
    bar.enable_steady_tick(std::time::Duration::from_millis(200));
    let spinner = Spinner(bar);
    let result = match workers {
        Some(workers) => {
            diagnosis::diagnose_with_store(campaign, &workers.evaluator(), store, &spinner)
        }
        None => diagnosis::diagnose_with_store(campaign, &LocalEvaluator, store, &spinner),
    };
    let result = result.and_then(|mut d| {
        if args.profile {
            spinner
                .0
                .set_message("profiling the likelihood of the selected effects");
            match workers {
                Some(workers) => diagnosis::profile_selected(&mut d, &workers.evaluator(), store)?,
                None => diagnosis::profile_selected(&mut d, &LocalEvaluator, store)?,
            }
        }
        Ok(d)
    });
    spinner.0.finish_and_clear();
    let d = result?;
    let found = if args.discover {
        let bar = ProgressBar::with_draw_target(None, ProgressDrawTarget::stderr());
        bar.set_message("discovering outside the library, refitting the proposal");
        let spinner = Spinner(bar);
        let found = match workers {
            Some(workers) => found_outside_the_library(&d, &workers.evaluator(), &spinner),
            None => found_outside_the_library(&d, &LocalEvaluator, &spinner),
        };
        spinner.0.finish_and_clear();
        Some(found?)
    } else {
        None
    };
    Ok((d, found))
}

/// The baseline, its residuals, the candidates, what was added and the parameters.
fn print_fit(d: &diagnosis::Diagnosis) {
    println!(
        "baseline: objective {:.4e} (held out {:.4e}), noise floor {:.4e}; {} of {} runs reached it",
        d.baseline.objective,
        d.baseline.held_out_objective,
        d.noise_floor,
        d.baseline.runs_at_best.count,
        d.baseline.runs_at_best.of
    );
    for (o, r) in d.campaign.outputs.iter().zip(&d.baseline.residual) {
        println!(
            "  {:<22} rms {:.4e}  Ljung-Box {:.1} (white below {:.1}): {}",
            o.model,
            r.rms,
            r.ljung_box,
            r.ljung_box_critical,
            if r.white { "white" } else { "structured" }
        );
    }
    println!("\ncandidates (score = share of the residual each could remove):");
    for c in d.candidates.iter().take(10) {
        let refit = c
            .objective
            .map_or(String::new(), |o| format!("  refitted: {o:.4e}"));
        println!("  {:<32} {:>7.4}{refit}", c.effect, c.score);
    }
    if !d.selected.is_empty() {
        println!("\nadded: {}", d.selected.join(" + "));
    }
    println!("\nparameters:");
    for p in &d.final_fit.parameters {
        println!(
            "  {:<28} {:>13.6e}  95% [{:.6e}, {:.6e}]",
            p.name, p.value, p.ci_low, p.ci_high
        );
    }
    for note in report::bound_notes(&d.final_fit) {
        println!("  note: {note}");
    }
}

/// The profiles' intervals, the objective before and after, the verdict and what discovery
/// found.
fn print_profiles_and_verdict(d: &diagnosis::Diagnosis, profile: bool, found: Option<&Found>) {
    if profile && d.profiles.is_empty() {
        println!("  (no effect selected: nothing to profile)");
    }
    for p in &d.profiles {
        let end = |v: Option<f64>| v.map_or_else(|| "open".to_string(), |v| format!("{v:.6e}"));
        println!(
            "  {:<28} profile 95% [{}, {}]{}",
            p.name,
            end(p.ci_low()),
            end(p.ci_high()),
            if p.identifiable() {
                ""
            } else {
                "  (not identifiable)"
            }
        );
    }
    println!(
        "\nobjective {:.4e} -> {:.4e}, held out {:.4e} -> {:.4e}",
        d.baseline.objective,
        d.final_fit.objective,
        d.baseline.held_out_objective,
        d.final_fit.held_out_objective
    );
    println!("\n{}", report::verdict_text(d));
    match found {
        Some(found) => println!("\n{}", found.text()),
        // Said where it matters: the library is not all there is.
        None if !d.explained() && d.campaign.model.info().name == "furuta" => println!(
            "\nThe effect library leaves {:.2}x the noise floor. `calib diagnose --discover` looks \
             outside it: the torque each joint still misses, from the record, and a harmonic \
             torque of every period 2-40 per turn (docs/discovery.md).",
            d.final_fit.objective / d.noise_floor
        ),
        None => {}
    }
}

/// diagnosis.json with discovery's entry, and diagnosis.md with its section.
fn add_to_outputs(out: &std::path::Path, json: &serde_json::Value, found: &Found) -> Outcome {
    let fail = |path: &std::path::Path, e: std::io::Error| {
        Failure::internal(format!("cannot write {}: {e}", path.display()))
    };
    let path = out.join("diagnosis.json");
    let pretty = serde_json::to_string_pretty(json).expect("plain data") + "\n";
    std::fs::write(&path, pretty).map_err(|e| fail(&path, e))?;
    let path = out.join("diagnosis.md");
    let mut md = std::fs::read_to_string(&path).map_err(|e| fail(&path, e))?;
    md.push_str(&found.markdown());
    std::fs::write(&path, md).map_err(|e| fail(&path, e))?;
    Ok(())
}
