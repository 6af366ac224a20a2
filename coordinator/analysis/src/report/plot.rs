//! SVG plots: measured, nominal and calibrated over time, one file per output, as the
//! seed's figures show them. The fitted window is shaded.

use super::chart::{self, Chart, Scale};
use super::evidence::{best_threshold, BEST_TOLERANCE};
use crate::report::chart::RGBColor;
use calib_engine::calibration::Calibration;
use calib_engine::campaign::Experiment;
use calib_engine::error::{Error, Result};
use calib_engine::measurement::Measurement;
use calib_engine::objective::Objective;
use calib_model::ModelInfo;
use calib_model::Run;
use std::path::{Path, PathBuf};

pub use super::chart::{Dash, Series};

/// Points per simulated curve.
const CURVE_POINTS: usize = 2000;

/// Measured data: a thin near-black line drawn above the models, so it never disappears
/// under a thicker coloured model curve.
pub const MEASURED: RGBColor = RGBColor(25, 25, 25);
/// The nominal model: red, dashed.
pub const NOMINAL: RGBColor = RGBColor(220, 50, 47);
/// The calibrated model: a thick blue line.
pub const CALIBRATED: RGBColor = RGBColor(38, 139, 210);

pub use super::runs::run_label;

/// An axis label with its unit, `name [unit]`, or the name alone when the unit is unknown.
pub fn with_unit(name: &str, unit: &str) -> String {
    if unit.trim().is_empty() {
        name.to_string()
    } else {
        format!("{name} [{unit}]")
    }
}

fn write_svg(path: &Path, text: &str) -> Result<()> {
    std::fs::write(path, text).map_err(|source| Error::Write {
        path: path.to_path_buf(),
        source,
    })
}

/// A time plot of several series, the window `shade` (start, stop) shaded.
pub fn time_plot(
    path: &Path,
    title: &str,
    y_label: &str,
    series: &[Series],
    shade: Option<(f64, f64)>,
) -> Result<()> {
    line_plot(path, title, "time [s]", y_label, series, shade)
}

/// A plot of several series against a common abscissa (their `time`), the range `shade`
/// (start, stop) shaded.
pub fn line_plot(
    path: &Path,
    title: &str,
    x_label: &str,
    y_label: &str,
    series: &[Series],
    shade: Option<(f64, f64)>,
) -> Result<()> {
    let text = line_plot_svg(title, x_label, y_label, series, shade).map_err(|e| Error::Write {
        path: path.to_path_buf(),
        source: std::io::Error::other(e),
    })?;
    write_svg(path, &text)
}

/// The SVG text of [`line_plot`], or why it could not be drawn: the web app serves it
/// as it is.
pub fn line_plot_svg(
    title: &str,
    x_label: &str,
    y_label: &str,
    series: &[Series],
    shade: Option<(f64, f64)>,
) -> std::result::Result<String, String> {
    let shades: Vec<(f64, f64)> = shade.into_iter().collect();
    Ok(chart::render(&Chart {
        title,
        x_label,
        y_label,
        series,
        shades: &shades,
        ..Chart::default()
    }))
}

/// The SVG of a fit plot: the model curves `models` (label, times, values), the first
/// dashed red (the nominal model), the next thick blue (the calibrated one) and further ones
/// in the palette's colours, with the measured data drawn last, thin and dark, above them;
/// the fitted intervals `windows` shaded.
pub fn fit_svg(
    title: &str,
    y_label: &str,
    measured: (&[f64], &[f64]),
    models: &[(&str, &[f64], &[f64])],
    windows: &[(f64, f64)],
) -> String {
    let series: Vec<Series> = models
        .iter()
        .enumerate()
        .map(|(k, &(label, t, v))| match k {
            0 => Series::new(label, t, v, NOMINAL, 2).dashed(Dash::Dashed),
            1 => Series::new(label, t, v, CALIBRATED, 3),
            _ => {
                let (color, dash) = chart::style(k + 1);
                Series::new(label, t, v, color, 2).dashed(dash)
            }
        })
        .collect();
    with_measured(title, y_label, series, measured, windows)
}

/// The SVG of a comparison of several fits of one output: the measured data once, drawn
/// last, and each fit (`fits`: label, times, values) in its own colour and dash pattern.
pub fn comparison_svg(
    title: &str,
    y_label: &str,
    measured: (&[f64], &[f64]),
    fits: &[(String, Vec<f64>, Vec<f64>)],
    windows: &[(f64, f64)],
) -> String {
    let series: Vec<Series> = fits
        .iter()
        .enumerate()
        .map(|(k, (label, t, v))| {
            let (color, dash) = chart::style(k);
            Series::new(label, t, v, color, 2).dashed(dash)
        })
        .collect();
    with_measured(title, y_label, series, measured, windows)
}

/// The chart of `series` over time with the measured data drawn last (on top), the fitted
/// intervals `windows` shaded.
fn with_measured<'a>(
    title: &str,
    y_label: &str,
    mut series: Vec<Series<'a>>,
    measured: (&'a [f64], &'a [f64]),
    windows: &[(f64, f64)],
) -> String {
    series.push(Series::new("measured", measured.0, measured.1, MEASURED, 1));
    chart::render(&Chart {
        title,
        x_label: "time [s]",
        y_label,
        series: &series,
        shades: windows,
        ..Chart::default()
    })
}

/// The SVG of an input plot: the signal a model is driven by, the fitted intervals shaded.
pub fn input_svg(
    title: &str,
    y_label: &str,
    signal: (&[f64], &[f64]),
    windows: &[(f64, f64)],
) -> String {
    chart::render(&Chart {
        title,
        x_label: "time [s]",
        y_label,
        series: &[Series::new(
            "as the model is driven",
            signal.0,
            signal.1,
            RGBColor(133, 153, 0),
            2,
        )],
        shades: windows,
        ..Chart::default()
    })
}

/// `points` evenly spaced times over `[start, stop]`.
pub fn uniform_grid(start: f64, stop: f64, points: usize) -> Vec<f64> {
    (0..points)
        .map(|i| start + (stop - start) * i as f64 / (points - 1) as f64)
        .collect()
}

/// The indices of the samples of `time` within `[start, stop]`, the span a simulation covers.
fn simulated_span(time: &[f64], start: f64, stop: f64) -> Vec<usize> {
    (0..time.len())
        .filter(|&i| (start..=stop).contains(&time[i]))
        .collect()
}

/// One plot per experiment and output: measured, nominal model, calibrated model; and one
/// per driven input, the signal the model was given. A campaign of one record names its
/// plots after the outputs (`armJoint.phi.svg`), one of several experiments after the
/// experiment too (`swing.armJoint.phi.svg`, `driven.input.armTorque.svg`).
pub fn write_fit_plots(c: &Calibration, dir: &Path) -> Result<Vec<PathBuf>> {
    let campaign = &c.campaign;
    // The curves cover what is simulated: from the start time (an FMU's may be past 0).
    let start = campaign.solver.start_time;
    let several = !campaign.more.is_empty() || !campaign.experiment.is_empty();
    let mut written = Vec::new();
    for (k, (experiment, part)) in campaign
        .experiments()
        .into_iter()
        .zip(c.objective.experiments())
        .enumerate()
    {
        let loaded;
        let measurement = if k == 0 {
            &c.measurement
        } else {
            let columns: Vec<&str> = experiment
                .outputs
                .iter()
                .map(|o| o.measured.as_str())
                .collect();
            loaded = calib_engine::measurement::Measurement::load(
                &experiment.measurement_file,
                &experiment.time_column,
                &columns,
            )?;
            &loaded
        };
        let plots = ExperimentPlots {
            c,
            experiment: &experiment,
            part,
            measurement,
            several,
            start,
        };
        written.extend(plots.write(dir)?);
    }
    Ok(written)
}

/// The plots of one experiment of a calibration.
struct ExperimentPlots<'a> {
    c: &'a Calibration,
    experiment: &'a Experiment,
    part: &'a Objective,
    measurement: &'a Measurement,
    /// The campaign fits several experiments: plots are named and titled after each.
    several: bool,
    /// Where the curves start: what is simulated (an FMU's start time may be past 0).
    start: f64,
}

impl ExperimentPlots<'_> {
    /// Measured, nominal and calibrated for each output; the signal of each driven input.
    fn write(&self, dir: &Path) -> Result<Vec<PathBuf>> {
        let Self {
            c,
            experiment,
            start,
            ..
        } = *self;
        let campaign = &c.campaign;
        let info = campaign.model.info();
        let mut written = Vec::new();
        let (prefix, title) = self.names();
        let grid = uniform_grid(start, experiment.stop_time, CURVE_POINTS);
        let nominal = self.simulate(&grid, &campaign.nominal());
        let calibrated = self.simulate(&grid, &c.best_run().point);
        let page = Page {
            dir,
            prefix,
            title,
            grid,
            info,
        };
        self.write_outputs(&page, [&nominal, &calibrated], &mut written)?;
        self.write_inputs(&page, &mut written)?;
        Ok(written)
    }

    /// The file-name prefix and the title of this experiment's plots: its name, when the
    /// campaign fits several experiments, so that their plots do not collide.
    fn names(&self) -> (String, String) {
        let campaign = &self.c.campaign;
        let prefix = if self.several {
            format!("{}.", sanitize(&self.experiment.name))
        } else {
            String::new()
        };
        let title = if self.several {
            format!("{} ({})", campaign.name, self.experiment.name)
        } else {
            campaign.name.clone()
        };
        (prefix, title)
    }

    /// The outputs simulated at the free values `free` on `grid`, NaN throughout where the
    /// simulation fails (the plots are written all the same).
    fn simulate(&self, grid: &[f64], free: &[f64]) -> Vec<Vec<f64>> {
        let part = self.part;
        self.c
            .campaign
            .model
            .simulate(
                &Run::new(
                    &part.full_parameters(free),
                    grid,
                    &part.outputs,
                    &part.solver,
                )
                .driven(&part.inputs),
            )
            .map(|t| t.values)
            .unwrap_or_else(|_| vec![vec![f64::NAN; grid.len()]; part.outputs.len()])
    }

    /// One plot per output: the measured data over the simulated span against the nominal
    /// and the calibrated model (`models`, in that order).
    fn write_outputs(
        &self,
        page: &Page,
        models: [&[Vec<f64>]; 2],
        written: &mut Vec<PathBuf>,
    ) -> Result<()> {
        let Self {
            experiment,
            measurement,
            start,
            ..
        } = *self;
        let Page {
            dir,
            prefix,
            title,
            grid,
            info,
        } = page;
        let [nominal, calibrated] = models;
        let shown = simulated_span(&measurement.time, start, experiment.stop_time);
        let measured_time: Vec<f64> = shown.iter().map(|&i| measurement.time[i]).collect();
        for (j, o) in experiment.outputs.iter().enumerate() {
            let column = measurement.column(&o.measured).unwrap_or(&[]);
            let measured: Vec<f64> = shown
                .iter()
                .filter_map(|&i| column.get(i).copied())
                .collect();
            let unit = &info.outputs[o.model_index].unit;
            let path = dir.join(format!("{prefix}{}.svg", sanitize(&o.model)));
            write_svg(
                &path,
                &fit_svg(
                    &format!("{title}: {} vs measured {}", o.model, o.measured),
                    &with_unit(&o.model, unit),
                    (&measured_time, &measured),
                    &[
                        ("nominal model", grid, &nominal[j]),
                        ("calibrated model", grid, &calibrated[j]),
                    ],
                    &experiment.windows,
                ),
            )?;
            written.push(path);
        }
        Ok(())
    }

    /// One plot per driven input: the signal the simulations were driven with, on the grid.
    fn write_inputs(&self, page: &Page, written: &mut Vec<PathBuf>) -> Result<()> {
        let (prefix, title, grid) = (&page.prefix, &page.title, &page.grid);
        for signal in &self.part.inputs.signals {
            let spec = &page.info.inputs[signal.input];
            let values: Vec<f64> = grid.iter().map(|&t| signal.at(t)).collect();
            let path = page
                .dir
                .join(format!("{prefix}input.{}.svg", sanitize(&spec.name)));
            write_svg(
                &path,
                &input_svg(
                    &format!(
                        "{title}: input {} ({})",
                        spec.name,
                        signal.interpolation.as_str()
                    ),
                    &with_unit(&spec.name, &spec.unit),
                    (grid, &values),
                    &self.experiment.windows,
                ),
            )?;
            written.push(path);
        }
        Ok(())
    }
}

/// Where and under which names one experiment's plots go, and the grid their curves share.
struct Page<'a> {
    dir: &'a Path,
    /// Prefix of every file name (the experiment's, when there are several).
    prefix: String,
    title: String,
    grid: Vec<f64>,
    info: &'a ModelInfo,
}

/// The waterfall plot of a calibration (`waterfall.svg`): every run's final objective,
/// each run named by its method and start.
pub fn write_waterfall(c: &Calibration, dir: &Path) -> Result<PathBuf> {
    let runs: Vec<(String, f64)> = c
        .runs
        .iter()
        .map(|r| (run_label(r.method.name(), r.start), r.objective))
        .collect();
    let path = dir.join("waterfall.svg");
    waterfall_plot(
        &path,
        &format!(
            "{}: final objective of each run, best first",
            c.campaign.name
        ),
        &runs,
    )?;
    Ok(path)
}

/// The objectives sorted ascending, as drawn on a log scale: a value that is not positive
/// (an exact fit) is drawn a decade below the smallest positive one.
pub fn waterfall_values(objectives: &[f64]) -> Vec<f64> {
    let mut sorted = objectives.to_vec();
    sorted.sort_by(f64::total_cmp);
    let smallest = sorted
        .iter()
        .copied()
        .filter(|v| *v > 0.0 && v.is_finite())
        .fold(f64::INFINITY, f64::min);
    let floor = if smallest.is_finite() {
        smallest / 10.0
    } else {
        1e-12
    };
    sorted
        .into_iter()
        .map(|v| if v > 0.0 && v.is_finite() { v } else { floor })
        .collect()
}

/// A waterfall plot, as pyPESTO draws one: the runs' final objectives (`runs`: each run's
/// name and objective) sorted ascending on a log scale, those within [`BEST_TOLERANCE`] of
/// the best highlighted, each named below the axis. Many runs on the first step are the
/// evidence that the best was found; one alone is a warning.
pub fn waterfall_plot(path: &Path, title: &str, runs: &[(String, f64)]) -> Result<()> {
    write_svg(path, &waterfall_svg(title, runs))
}

/// The SVG text of [`waterfall_plot`].
pub fn waterfall_svg(title: &str, runs: &[(String, f64)]) -> String {
    let objectives: Vec<f64> = runs.iter().map(|r| r.1).collect();
    let values = waterfall_values(&objectives);
    let best = objectives.iter().copied().fold(f64::INFINITY, f64::min);
    let threshold = best_threshold(best);
    let mut order: Vec<usize> = (0..runs.len()).collect();
    order.sort_by(|&a, &b| objectives[a].total_cmp(&objectives[b]));
    let names: Vec<String> = order.iter().map(|&i| runs[i].0.clone()).collect();
    let at_best: Vec<bool> = order.iter().map(|&i| objectives[i] <= threshold).collect();
    let count = at_best.iter().filter(|b| **b).count();
    let n = values.len();
    let rank: Vec<f64> = (1..=n).map(|k| k as f64).collect();
    let pick = |mark: bool| -> Vec<f64> {
        values
            .iter()
            .zip(&at_best)
            .map(|(&v, &b)| if b == mark { v } else { f64::NAN })
            .collect()
    };
    let (best_values, other_values) = (pick(true), pick(false));
    let label = format!(
        "within {:.0}% of the best ({count} of {n})",
        100.0 * BEST_TOLERANCE
    );
    let series = [
        Series::new("", &rank, &values, RGBColor(150, 150, 150), 1),
        Series::new(&label, &rank, &best_values, CALIBRATED, 1).dots(5.0),
        Series::new(
            "other runs",
            &rank,
            &other_values,
            RGBColor(150, 150, 150),
            1,
        )
        .dots(5.0),
    ];
    chart::render(&Chart {
        title,
        x_label: "run, sorted by final objective",
        y_label: "final objective",
        series: &series,
        y_scale: Scale::Log,
        categories: &names,
        size: (900, 480),
        ..Chart::default()
    })
}

/// A file name from an output name (`armJoint.phi` → `armJoint.phi`, `a/b` → `a_b`).
pub fn sanitize(name: &str) -> String {
    name.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '.' || c == '-' || c == '_' {
                c
            } else {
                '_'
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fit_curves_cover_the_simulated_span_from_its_start() {
        assert_eq!(uniform_grid(2.0, 6.0, 5), [2.0, 3.0, 4.0, 5.0, 6.0]);
        assert_eq!(uniform_grid(0.0, 1.0, 3), [0.0, 0.5, 1.0]);
        let time = [0.0, 1.0, 2.0, 3.0, 4.0, 5.0];
        assert_eq!(simulated_span(&time, 2.0, 4.0), [2, 3, 4]);
        assert_eq!(simulated_span(&time, 0.0, 10.0), [0, 1, 2, 3, 4, 5]);
    }

    #[test]
    fn waterfall_values_are_sorted_and_positive() {
        assert_eq!(
            waterfall_values(&[3.0, 0.0, 1.0, 1e30]),
            vec![0.1, 1.0, 3.0, 1e30]
        );
        assert_eq!(waterfall_values(&[0.0]), vec![1e-12]);
    }

    #[test]
    fn a_waterfall_plot_marks_the_runs_at_the_best() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("waterfall.svg");
        let runs: Vec<(String, f64)> = [1.0, 1.005, 40.0, 2.0e3, 0.9999]
            .iter()
            .enumerate()
            .map(|(i, &v)| (run_label("nelder-mead", i), v))
            .collect();
        waterfall_plot(&path, "runs", &runs).unwrap();
        let svg = std::fs::read_to_string(&path).unwrap();
        assert!(svg.contains("within 1% of the best (3 of 5)"), "{svg}");
        assert!(svg.contains("other runs"));
        // One circle per run and one per legend entry.
        assert_eq!(svg.matches("<circle").count(), 5 + 2);
        // Each run named by method and start, best first.
        let a = chart::anatomy(&svg);
        assert_eq!(
            a.x_ticks,
            [
                "nelder-mead #4",
                "nelder-mead #0",
                "nelder-mead #1",
                "nelder-mead #2",
                "nelder-mead #3"
            ]
        );
        assert_eq!(a.y_scale, "log");
        assert!(a.faults().is_empty(), "{:?}", a.faults());
    }
}
