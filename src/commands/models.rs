use super::Outcome;
use calib_worker::models;

#[derive(clap::Args)]
pub struct Args {
    /// Print the descriptions as JSON.
    #[arg(long)]
    json: bool,
    /// Only this model: a hosted model's name, or the path of an FMU (`Model.fmu`).
    model: Option<String>,
    /// For an FMU: describe it as run through this interface (default: Model Exchange when
    /// it has it).
    #[arg(long, value_enum)]
    interface: Option<super::fmu::InterfaceArg>,
}

pub fn run(args: Args) -> Outcome {
    let selected: Vec<_> = match &args.model {
        Some(name) => vec![super::fmu::model(name, args.interface)?.info()],
        None => models::all().iter().map(|m| m.info()).collect(),
    };
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
