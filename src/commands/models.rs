use super::Outcome;
use calib_model::models;

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

/// The solver settings a simulation of `model` gets unless told otherwise, and where its
/// tolerance comes from.
fn default_solver(model: &dyn calib_model::Model) -> serde_json::Value {
    let o = model.default_options();
    serde_json::json!({
        "rtol": o.rtol,
        "atol": o.atol,
        "max_steps": o.max_steps,
        "tolerance_origin": model.tolerance_origin(),
        "communication_step": o.communication_step,
    })
}

pub fn run(args: Args) -> Outcome {
    let selected: Vec<&dyn calib_model::Model> = match &args.model {
        Some(name) => vec![super::fmu::model(name, args.interface)?],
        None => models::all().iter().map(|m| m.as_ref()).collect(),
    };
    if args.json {
        let described: Vec<serde_json::Value> = selected
            .iter()
            .map(|m| {
                let mut v = serde_json::to_value(m.info()).expect("plain data");
                v["default_solver"] = default_solver(*m);
                v["places"] = serde_json::to_value(m.places()).expect("plain data");
                v
            })
            .collect();
        println!(
            "{}",
            serde_json::to_string_pretty(&described).expect("plain data")
        );
        return Ok(());
    }
    for model in selected {
        let info = model.info();
        println!(
            "{} (version {}): {}",
            info.name, info.version, info.description
        );
        let o = model.default_options();
        print!(
            "  tolerance: rtol {:e} (atol {:e}), {}",
            o.rtol,
            o.atol,
            model.tolerance_origin()
        );
        match o.communication_step {
            Some(h) => println!("; communication step {h} s (the FMU's default experiment)"),
            None => println!(),
        }
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
        if info.inputs.is_empty() {
            println!("  inputs: none");
        } else {
            println!("  inputs (driven by `calib simulate --input`, campaigns' [[inputs]]):");
            for i in &info.inputs {
                println!("    {:<22} {:<8} {}", i.name, i.unit, i.description);
            }
        }
        println!("  effects (0 = absent):");
        for e in &info.effects {
            println!(
                "    {:<28} [{}, {}] {:<12} {}",
                e.name, e.min, e.max, e.unit, e.description
            );
        }
        println!("  places of effects defined by a formula (campaigns' [[effects]] `formula`):");
        for p in model.places() {
            let key = format!("{} = \"{}\"", p.kind.word(), p.name);
            println!("    {key:<34} {}", p.description);
        }
        let states = model.state_names();
        if !states.is_empty() {
            println!(
                "    (a torque's formula reads the state as {})",
                states.join(", ")
            );
        }
        println!();
    }
    Ok(())
}
