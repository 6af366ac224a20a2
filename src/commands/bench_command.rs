//! `calib bench command`: what one run of a command model costs beside the command's own
//! time (the old outputs removed, the templates written, the process group, the wait, the
//! outputs read), measured with a command that only writes its output (the shell's `echo`) in a slot's folder,
//! against the same command started and waited for alone; and what making a slot's folder
//! costs, once per slot.

use super::bench_store::Scratch;
use super::{Failure, Outcome};
use calib_model::command::{CommandModel, Instructions, Template};
use std::collections::BTreeMap;
use std::time::{Duration, Instant};

#[derive(clap::Args)]
pub struct Args {
    /// Runs of each measurement (the median is reported).
    #[arg(long, default_value_t = 201)]
    repeat: usize,
    /// Files in the model's folder beside the template and the output (copied once per slot).
    #[arg(long, default_value_t = 10)]
    files: usize,
}

fn timed(f: impl FnOnce() -> Result<(), Failure>) -> Result<Duration, Failure> {
    let start = Instant::now();
    f()?;
    Ok(start.elapsed())
}

fn middle(mut samples: Vec<Duration>) -> Duration {
    samples.sort();
    samples[samples.len() / 2]
}

fn median(repeat: usize, mut f: impl FnMut() -> Result<(), Failure>) -> Result<Duration, Failure> {
    f()?;
    let samples = (0..repeat.max(1))
        .map(|_| timed(&mut f))
        .collect::<Result<Vec<_>, _>>()?;
    Ok(middle(samples))
}

pub fn run(args: Args) -> Outcome {
    let io = |e: std::io::Error| Failure::internal(format!("bench folder: {e}"));
    let (folder, scratch) = (
        Scratch::new("command-model")?,
        Scratch::new("command-runs")?,
    );
    let (folder, scratch) = (&folder.0, &scratch.0);
    for k in 0..args.files {
        std::fs::write(folder.join(format!("data{k}.txt")), "1 2 3\n".repeat(100)).map_err(io)?;
    }
    // The command writes its output with the shell's own `echo`: nothing else runs.
    let command = "echo 'y = 1.5' > out.txt";
    let model = CommandModel {
        folder: folder.clone(),
        command: command.into(),
        templates: vec![(
            Template::parse("ptf #\nk = #k          #\n", "in.tpl")
                .map_err(|e| Failure::internal(e.to_string()))?,
            "in.txt".into(),
        )],
        instructions: vec![(
            Instructions::parse("pif @\n@y =@ !y!\n", "out.ins")
                .map_err(|e| Failure::internal(e.to_string()))?,
            "out.txt".into(),
        )],
        deadline: Duration::from_secs(60),
    };
    let values = BTreeMap::from([("k".to_string(), 2.5)]);
    let failed = |e: calib_model::command::RunFailure| Failure::internal(e.to_string());
    let prepare = median(args.repeat, || {
        model.prepare(scratch).map(drop).map_err(failed)
    })?;
    let slot = model.prepare(scratch).map_err(failed)?;
    let alone = || {
        std::process::Command::new("/bin/sh")
            .args(["-c", command])
            .current_dir(folder)
            .status()
            .map(drop)
            .map_err(|e| Failure::internal(format!("sh: {e}")))
    };
    let whole = || model.run_in(&slot, &values).map(drop).map_err(failed);
    // In turn, so that both see the same machine.
    let (mut alone_times, mut whole_times) = (Vec::new(), Vec::new());
    for _ in 0..args.repeat.max(1) {
        alone_times.push(timed(alone)?);
        whole_times.push(timed(whole)?);
    }
    let (alone, whole) = (middle(alone_times), middle(whole_times));
    let ms = |d: Duration| d.as_secs_f64() * 1e3;
    println!(
        "command model, a command that only writes its output (`{command}`), {} files in its \
         folder, medians of {}:",
        args.files, args.repeat
    );
    println!("  the command alone (sh -c):          {:.3} ms", ms(alone));
    println!(
        "  a slot's run folder, made once:     {:.3} ms (the model's folder copied)",
        ms(prepare)
    );
    println!("  one run of the command model:      {:.3} ms", ms(whole));
    println!(
        "  the run's own cost beside the command: {:.3} ms (target <= 2 ms)",
        ms(whole.saturating_sub(alone))
    );
    Ok(())
}
