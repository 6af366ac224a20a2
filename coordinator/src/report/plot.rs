//! SVG plots: measured, nominal and calibrated over time, one file per output, as the
//! seed's figures show them. The fitted window is shaded.

use super::evidence::{best_threshold, BEST_TOLERANCE};
use crate::calibration::Calibration;
use crate::error::{Error, Result};
use plotters::prelude::*;
use std::path::{Path, PathBuf};

/// Points per simulated curve.
const CURVE_POINTS: usize = 2000;

/// One series of a time plot.
pub struct Series<'a> {
    pub label: &'a str,
    pub time: &'a [f64],
    pub values: &'a [f64],
    pub color: RGBColor,
    pub width: u32,
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

/// A time plot of several series, each fitted interval of `windows` shaded.
fn time_plot_windows(
    path: &Path,
    title: &str,
    y_label: &str,
    series: &[Series],
    windows: &[(f64, f64)],
) -> Result<()> {
    let text = plot_svg(title, "time [s]", y_label, series, windows).map_err(|e| Error::Write {
        path: path.to_path_buf(),
        source: std::io::Error::other(e),
    })?;
    std::fs::write(path, text).map_err(|source| Error::Write {
        path: path.to_path_buf(),
        source,
    })
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
    std::fs::write(path, text).map_err(|source| Error::Write {
        path: path.to_path_buf(),
        source,
    })
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
    plot_svg(title, x_label, y_label, series, &shades)
}

/// [`line_plot_svg`] with any number of shaded ranges.
fn plot_svg(
    title: &str,
    x_label: &str,
    y_label: &str,
    series: &[Series],
    shades: &[(f64, f64)],
) -> std::result::Result<String, String> {
    let (mut x0, mut x1, mut y0, mut y1) = (
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
    );
    for s in series {
        for (&t, &v) in s.time.iter().zip(s.values) {
            if t.is_finite() && v.is_finite() {
                x0 = x0.min(t);
                x1 = x1.max(t);
                y0 = y0.min(v);
                y1 = y1.max(v);
            }
        }
    }
    if !x0.is_finite() {
        (x0, x1, y0, y1) = (0.0, 1.0, 0.0, 1.0);
    }
    if x0 >= x1 {
        x1 = x0 + 1.0;
    }
    if y0 >= y1 {
        y0 -= 0.5;
        y1 += 0.5;
    }
    let pad = 0.05 * (y1 - y0);
    let (y0, y1) = (y0 - pad, y1 + pad);
    let mut text = String::new();
    let draw = |text: &mut String| -> std::result::Result<(), Box<dyn std::error::Error>> {
        let root = SVGBackend::with_string(text, (1000, 500)).into_drawing_area();
        root.fill(&WHITE)?;
        let mut chart = ChartBuilder::on(&root)
            .caption(title, ("sans-serif", 20))
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(70)
            .build_cartesian_2d(x0..x1, y0..y1)?;
        chart
            .configure_mesh()
            .x_desc(x_label)
            .y_desc(y_label)
            .light_line_style(WHITE.mix(0.0))
            .draw()?;
        for &(a, b) in shades {
            chart.draw_series(std::iter::once(Rectangle::new(
                [(a.max(x0), y0), (b.min(x1), y1)],
                RGBColor(235, 242, 250).filled(),
            )))?;
        }
        for s in series {
            let color = s.color;
            let width = s.width;
            let drawn = chart.draw_series(LineSeries::new(
                s.time
                    .iter()
                    .zip(s.values)
                    .filter(|(t, v)| t.is_finite() && v.is_finite())
                    .map(|(&t, &v)| (t, v)),
                color.stroke_width(width),
            ))?;
            // Series without a label (a second band edge, say) stay out of the legend.
            if !s.label.is_empty() {
                drawn.label(s.label).legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(2))
                });
            }
        }
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperRight)
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .draw()?;
        root.present()?;
        Ok(())
    };
    draw(&mut text).map_err(|e| e.to_string())?;
    Ok(text)
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
    let info = campaign.model.info();
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
            loaded = crate::measurement::Measurement::load(
                &experiment.measurement_file,
                &experiment.time_column,
                &columns,
            )?;
            &loaded
        };
        let prefix = if several {
            format!("{}.", sanitize(&experiment.name))
        } else {
            String::new()
        };
        let title = if several {
            format!("{} ({})", campaign.name, experiment.name)
        } else {
            campaign.name.clone()
        };
        let grid = uniform_grid(start, experiment.stop_time, CURVE_POINTS);
        let simulate = |free: &[f64]| {
            campaign
                .model
                .simulate_driven(
                    &part.full_parameters(free),
                    &grid,
                    &part.outputs,
                    &part.solver,
                    &part.inputs,
                )
                .map(|t| t.values)
                .unwrap_or_else(|_| vec![vec![f64::NAN; grid.len()]; part.outputs.len()])
        };
        let nominal = simulate(&campaign.nominal());
        let calibrated = simulate(&c.best_run().point);
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
            time_plot_windows(
                &path,
                &format!("{title}: {} vs measured {}", o.model, o.measured),
                &format!("{} [{unit}]", o.model),
                &[
                    Series {
                        label: "measured",
                        time: &measured_time,
                        values: &measured,
                        color: RGBColor(120, 120, 120),
                        width: 1,
                    },
                    Series {
                        label: "nominal",
                        time: &grid,
                        values: &nominal[j],
                        color: RGBColor(220, 50, 47),
                        width: 1,
                    },
                    Series {
                        label: "calibrated",
                        time: &grid,
                        values: &calibrated[j],
                        color: RGBColor(38, 139, 210),
                        width: 2,
                    },
                ],
                &experiment.windows,
            )?;
            written.push(path);
        }
        for signal in &part.inputs.signals {
            let spec = &info.inputs[signal.input];
            let values: Vec<f64> = grid.iter().map(|&t| signal.at(t)).collect();
            let path = dir.join(format!("{prefix}input.{}.svg", sanitize(&spec.name)));
            time_plot_windows(
                &path,
                &format!(
                    "{title}: input {} ({})",
                    spec.name,
                    signal.interpolation.as_str()
                ),
                &format!("{} [{}]", spec.name, spec.unit),
                &[Series {
                    label: "as the model is driven",
                    time: &grid,
                    values: &values,
                    color: RGBColor(133, 153, 0),
                    width: 1,
                }],
                &experiment.windows,
            )?;
            written.push(path);
        }
    }
    Ok(written)
}

/// The waterfall plot of a calibration (`waterfall.svg`): every run's final objective.
pub fn write_waterfall(c: &Calibration, dir: &Path) -> Result<PathBuf> {
    let objectives: Vec<f64> = c.runs.iter().map(|r| r.objective).collect();
    let path = dir.join("waterfall.svg");
    waterfall_plot(
        &path,
        &format!(
            "{}: final objective of each run, best first",
            c.campaign.name
        ),
        &objectives,
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

/// A waterfall plot, as pyPESTO draws one: the runs' final objectives sorted ascending on a
/// log scale, those within [`BEST_TOLERANCE`] of the best highlighted. Many runs on the
/// first step are the evidence that the best was found; one alone is a warning.
pub fn waterfall_plot(path: &Path, title: &str, objectives: &[f64]) -> Result<()> {
    let values = waterfall_values(objectives);
    let best = objectives.iter().copied().fold(f64::INFINITY, f64::min);
    let threshold = best_threshold(best);
    let mut sorted = objectives.to_vec();
    sorted.sort_by(f64::total_cmp);
    let at_best: Vec<bool> = sorted.iter().map(|v| *v <= threshold).collect();
    let count = at_best.iter().filter(|b| **b).count();
    let n = values.len();
    let lowest = values.iter().copied().fold(f64::INFINITY, f64::min);
    let highest = values.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let (y0, y1) = if lowest.is_finite() {
        (lowest / 2.0, highest * 2.0)
    } else {
        (0.1, 10.0)
    };
    let highlight = RGBColor(38, 139, 210);
    let other = RGBColor(150, 150, 150);
    let draw = || -> std::result::Result<(), Box<dyn std::error::Error>> {
        let root = SVGBackend::new(path, (800, 450)).into_drawing_area();
        root.fill(&WHITE)?;
        let mut chart = ChartBuilder::on(&root)
            .caption(title, ("sans-serif", 20))
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(80)
            .build_cartesian_2d(0.5..(n.max(1) as f64 + 0.5), (y0..y1).log_scale())?;
        chart
            .configure_mesh()
            .x_desc("run, sorted by final objective")
            .y_desc("final objective")
            .x_labels(n.clamp(1, 20))
            .x_label_formatter(&|x| format!("{x:.0}"))
            .y_label_formatter(&|y| format!("{y:.2e}"))
            .light_line_style(WHITE.mix(0.0))
            .draw()?;
        chart.draw_series(LineSeries::new(
            values.iter().enumerate().map(|(i, &v)| (i as f64 + 1.0, v)),
            other.stroke_width(1),
        ))?;
        let label = format!(
            "within {:.0}% of the best ({count} of {n})",
            100.0 * BEST_TOLERANCE
        );
        for (mark, color, label) in [
            (true, highlight, label),
            (false, other, "other runs".into()),
        ] {
            chart
                .draw_series(
                    values
                        .iter()
                        .zip(&at_best)
                        .enumerate()
                        .filter(|(_, (_, b))| **b == mark)
                        .map(|(i, (&v, _))| Circle::new((i as f64 + 1.0, v), 5, color.filled())),
                )?
                .label(label)
                .legend(move |(x, y)| Circle::new((x + 10, y), 5, color.filled()));
        }
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperLeft)
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .draw()?;
        root.present()?;
        Ok(())
    };
    draw().map_err(|e| Error::Write {
        path: path.to_path_buf(),
        source: std::io::Error::other(e.to_string()),
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
        waterfall_plot(&path, "runs", &[1.0, 1.005, 40.0, 2.0e3, 0.9999]).unwrap();
        let svg = std::fs::read_to_string(&path).unwrap();
        assert!(svg.contains("within 1% of the best (3 of 5)"), "{svg}");
        assert!(svg.contains("other runs"));
        // One circle per run and one per legend entry.
        assert_eq!(svg.matches("<circle").count(), 5 + 2);
    }
}
