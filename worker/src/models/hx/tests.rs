//! Physics checks of both models.

use super::*;

fn grid(step: f64, end: f64) -> Vec<f64> {
    let n = (end / step).round() as usize;
    (0..=n).map(|i| i as f64 * step).collect()
}

fn run(model: &HxModel, params: &[f64], step: f64) -> Trajectory {
    let outputs: Vec<usize> = (0..OUTPUTS.len()).collect();
    model
        .simulate(
            params,
            &grid(step, 300.0),
            &outputs,
            &SolverOptions::default(),
        )
        .expect("simulation")
}

#[test]
#[ignore = "prints the nominal trajectories"]
fn print_nominal() {
    for model in [highfi(), lowfi()] {
        let p = model.info().default_vector();
        let t0 = std::time::Instant::now();
        let tr = run(&model, &p, 10.0);
        println!("{} {:?} {:?}", model.info().name, t0.elapsed(), tr.stats);
        for (k, t) in tr.time.iter().enumerate() {
            let row: Vec<String> = tr.values.iter().map(|v| format!("{:9.3}", v[k])).collect();
            println!("{t:5.0} {}", row.join(" "));
        }
    }
}
