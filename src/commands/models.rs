use super::Outcome;
use calib_worker::models;

#[derive(clap::Args)]
pub struct Args {
    /// Print the descriptions as JSON.
    #[arg(long)]
    json: bool,
    /// Only this model.
    model: Option<String>,
}

pub fn run(args: Args) -> Outcome {
    let selected: Vec<_> = models::all()
        .iter()
        .map(|m| m.info())
        .filter(|i| args.model.as_ref().is_none_or(|n| *n == i.name))
        .collect();
    if let Some(name) = &args.model {
        calib_worker::validate::model(name).map_err(|e| super::Failure::input(e.message))?;
    }
    if args.json {
        println!(
            "{}",
            serde_json::to_string_pretty(&selected).expect("plain data")
        );
        return Ok(());
    }
    for info in selected {
        println!(
            "{} (version {}): {}",
            info.name, info.version, info.description
        );
        println!("  parameters:");
        for p in &info.parameters {
            println!(
                "    {:<18} {:>12} [{}, {}] {:<10} {}",
                p.name, p.default, p.min, p.max, p.unit, p.description
            );
        }
        println!("  outputs:");
        for o in &info.outputs {
            println!("    {:<22} {:<8} {}", o.name, o.unit, o.description);
        }
        println!("  effects (0 = absent):");
        for e in &info.effects {
            println!(
                "    {:<28} [{}, {}] {:<12} {}",
                e.name, e.min, e.max, e.unit, e.description
            );
        }
        println!();
    }
    Ok(())
}
