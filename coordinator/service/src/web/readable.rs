//! Every kind of plot calib draws, checked the way a reader looks at it: at a narrow range
//! of values (0.0010 to 0.0011, 9.042860 to 9.042866) and across decades, the tick labels
//! all differ, none reads "-0", the legend box stays off the data area, and values spanning
//! decades are drawn on a log axis where the plot kind asks for one. With
//! `CALIB_PLOT_GALLERY` set to a folder, the plots are also written there to be looked at.

use super::plots::{draw, PlotRequest, PlotSeries, SeriesSet};
use calib_analysis::report::chart::RGBColor;
use calib_analysis::report::chart::{anatomy, Anatomy, Bars};
use calib_analysis::report::plot::{comparison_svg, fit_svg, input_svg, waterfall_svg};

/// `n` values from `lo` to `hi`, evenly spaced (`log`: evenly in log10).
fn ramp(lo: f64, hi: f64, n: usize, log: bool) -> Vec<f64> {
    (0..n)
        .map(|i| {
            let f = i as f64 / (n - 1) as f64;
            if log {
                10f64.powf(lo.log10() + f * (hi.log10() - lo.log10()))
            } else {
                lo + f * (hi - lo)
            }
        })
        .collect()
}

/// A wave between `lo` and `hi` over `time`.
fn wave(time: &[f64], lo: f64, hi: f64, phase: f64) -> Vec<f64> {
    time.iter()
        .map(|t| lo + (hi - lo) * 0.5 * (1.0 + (t * 0.7 + phase).sin()))
        .collect()
}

/// The ranges every plot is drawn over: (name, low, high, whether across decades).
const RANGES: [(&str, f64, f64, bool); 4] = [
    ("narrow", 0.0010, 0.0011, false),
    ("offset", 9.042860, 9.042866, false),
    ("decades", 1e-6, 1e3, true),
    ("negative", -2.5e-4, 1e-4, false),
];

/// Check `svg`, keep it in the gallery, and return what it is made of.
fn look(kind: &str, range: &str, svg: &str) -> Anatomy {
    if let Some(folder) = std::env::var_os("CALIB_PLOT_GALLERY") {
        let folder = std::path::PathBuf::from(folder);
        std::fs::create_dir_all(&folder).unwrap();
        std::fs::write(folder.join(format!("{kind}_{range}.svg")), svg).unwrap();
    }
    let a = anatomy(svg);
    assert!(
        a.faults().is_empty(),
        "{kind} at the {range} range: {:?}\n{a:?}",
        a.faults()
    );
    a
}

fn series(label: &str, x: &[f64], y: &[f64]) -> PlotSeries {
    PlotSeries {
        label: label.into(),
        x: x.iter().map(|v| Some(*v)).collect(),
        y: y.iter().map(|v| Some(*v)).collect(),
    }
}

#[test]
fn fit_plots_read_at_every_range() {
    let grid = ramp(0.0, 40.0, 400, false);
    let measured_time = ramp(0.0, 40.0, 4000, false);
    for (range, lo, hi, _) in RANGES {
        let measured = wave(&measured_time, lo, hi, 0.0);
        let nominal = wave(&grid, lo, hi, 0.4);
        let calibrated = wave(&grid, lo, hi, 0.02);
        let svg = fit_svg(
            "furuta: armJoint.phi vs measured phi_arm_rad",
            "armJoint.phi [rad]",
            (&measured_time, &measured),
            &[
                ("nominal model", &grid, &nominal),
                ("calibrated model", &grid, &calibrated),
            ],
            &[(5.0, 35.0)],
        );
        let a = look("fit", range, &svg);
        assert_eq!(a.y_scale, "linear");
        // The measured data is drawn last, above both models.
        let last = svg.rfind("<polyline").unwrap();
        assert!(svg[last..].contains("rgb(25,25,25)"), "measured not on top");
        assert!(svg.contains("time [s]") && svg.contains("armJoint.phi [rad]"));
    }
}

#[test]
fn input_plots_read_at_every_range() {
    let grid = ramp(0.0, 300.0, 600, false);
    for (range, lo, hi, _) in RANGES {
        let signal = wave(&grid, lo, hi, 1.0);
        let svg = input_svg(
            "hx: input m_dot (linear)",
            "m_dot [kg/s]",
            (&grid, &signal),
            &[],
        );
        look("input", range, &svg);
    }
}

#[test]
fn progress_plots_use_a_log_axis_across_decades() {
    let evaluations = ramp(1.0, 500.0, 50, false);
    for (range, lo, hi, decades) in RANGES {
        if lo <= 0.0 {
            continue;
        }
        let runs: Vec<PlotSeries> = (0..12)
            .map(|r| {
                // Each run falls from `hi` towards `lo` at its own pace.
                let best: Vec<f64> = evaluations
                    .iter()
                    .map(|e| lo + (hi - lo) * (-(e / (30.0 + 20.0 * r as f64))).exp())
                    .collect();
                let method = ["nelder-mead", "powell", "differential-evolution"][r % 3];
                series(
                    &calib_analysis::report::plot::run_label(method, r / 3),
                    &evaluations,
                    &best,
                )
            })
            .collect();
        let request = PlotRequest {
            title: "best objective of each run".into(),
            x_label: "evaluations (all runs)".into(),
            y_label: "best objective".into(),
            series: runs,
            y_scale: "auto".into(),
            direct_labels: true,
            ..PlotRequest::default()
        };
        let svg = draw(&request).unwrap_or_else(|_| panic!("the plot is refused"));
        let a = look("progress", range, &svg);
        assert_eq!(a.y_scale, if decades { "log" } else { "linear" }, "{range}");
        if decades {
            // Decade ticks: every label a power of ten.
            let decade = |t: &String| {
                t.parse::<f64>()
                    .is_ok_and(|v| (v.log10() - v.log10().round()).abs() < 1e-9)
            };
            assert!(a.y_ticks.len() >= 5, "{:?}", a.y_ticks);
            assert!(a.y_ticks.iter().all(decade), "{:?}", a.y_ticks);
        }
        assert!(svg.contains("differential-evolution #3"), "runs named");
        // Twelve runs, twelve different looks (colour and dash pattern).
        let looks: std::collections::BTreeSet<String> = svg
            .split("<polyline")
            .skip(1)
            .map(|p| {
                let stroke = p.split("stroke=\"").nth(1).unwrap_or("").split('"').next();
                let dash = p
                    .split("stroke-dasharray=\"")
                    .nth(1)
                    .map(|d| d.split('"').next());
                format!("{stroke:?} {dash:?}")
            })
            .collect();
        assert_eq!(looks.len(), 12, "{looks:?}");
    }
}

#[test]
fn waterfall_plots_read_at_every_range() {
    for (range, lo, hi, decades) in RANGES {
        if lo <= 0.0 {
            continue;
        }
        let runs: Vec<(String, f64)> = ramp(lo, hi, 9, decades)
            .into_iter()
            .enumerate()
            .map(|(i, v)| (calib_analysis::report::plot::run_label("powell", i), v))
            .collect();
        let svg = waterfall_svg("hx: final objective of each run, best first", &runs);
        let a = look("waterfall", range, &svg);
        assert_eq!(a.y_scale, "log");
        assert_eq!(a.x_ticks.len(), 9);
        assert_eq!(a.x_ticks[0], "powell #0");
    }
}

#[test]
fn profile_plots_read_at_every_range() {
    for (range, lo, hi, _) in RANGES {
        // The parameter's profile over [lo, hi], its minimum in the middle.
        let xs = ramp(lo, hi, 21, false);
        let mid = (lo + hi) / 2.0;
        let half = (hi - lo) / 2.0;
        let rises: Vec<f64> = xs
            .iter()
            .map(|x| 4.0 * ((x - mid) / half).powi(2))
            .collect();
        let grid = ramp(lo, hi, 201, false);
        let parabola: Vec<f64> = grid
            .iter()
            .map(|x| 3.0 * ((x - mid) / half).powi(2))
            .collect();
        let svg = calib_analysis::profile::report::profile_svg(
            "furuta: profile of pendulumFriction (identifiable)",
            "pendulumFriction [N.m.s/rad]",
            (&xs, &rises),
            (&grid, &parabola),
            3.84,
            (mid - 0.5 * half, mid + 0.5 * half),
        );
        let a = look("profile", range, &svg);
        assert!(a.x_ticks.len() >= 4, "{:?}", a.x_ticks);
    }
}

#[test]
fn sensitivity_bars_read_at_every_range() {
    let names: Vec<String> = [
        "armFriction",
        "pendulumFriction",
        "pendulumDamping",
        "dp_ref",
    ]
    .iter()
    .map(|s| s.to_string())
    .collect();
    for (range, lo, hi, decades) in RANGES {
        let first = ramp(lo, hi, 4, decades && lo > 0.0);
        let total: Vec<f64> = first.iter().map(|v| v * 1.05).collect();
        let intervals: Vec<(f64, f64)> = first.iter().map(|v| (v * 0.9, v * 1.1)).collect();
        let bars = [
            Bars {
                label: "first-order index",
                values: &first,
                intervals: &intervals,
                color: RGBColor(38, 139, 210),
            },
            Bars {
                label: "total index",
                values: &total,
                intervals: &[],
                color: RGBColor(203, 75, 22),
            },
        ];
        let svg = calib_analysis::sensitivity::report::bar_chart_svg(
            "hx: sensitivity of the objective",
            "Sobol index (95% bootstrap interval)",
            &names,
            &bars,
        );
        let a = look("sensitivity", range, &svg);
        assert_eq!(a.x_ticks, names);
    }
}

#[test]
fn model_tab_overlays_read_at_every_range() {
    let times = ramp(0.0, 40.0, 400, false);
    for (range, lo, hi, _) in RANGES {
        let before = wave(&times, lo, hi, 0.0);
        let after = wave(&times, lo, hi, 0.6);
        let request = PlotRequest {
            title: "furuta: pendulumJoint.phi".into(),
            x_label: "time [s]".into(),
            y_label: "pendulumJoint.phi [rad]".into(),
            series: vec![series("simulated", &times, &after)],
            overlays: vec![SeriesSet {
                label: "previous".into(),
                series: vec![series("simulated", &times, &before)],
            }],
            ..PlotRequest::default()
        };
        let svg = draw(&request).unwrap_or_else(|_| panic!("the plot is refused"));
        look("overlay", range, &svg);
        assert!(svg.contains("previous: simulated"));
        // The previous simulation dashed and under the new one.
        let first = svg.find("<polyline").unwrap();
        let second = svg[first + 1..].find("<polyline").unwrap() + first + 1;
        assert!(svg[first..second].contains("stroke-dasharray"));
        let new = svg[second..].split('>').next().unwrap();
        assert!(!new.contains("stroke-dasharray"), "{new}");
    }
}

#[test]
fn comparisons_read_at_every_range() {
    let measured_time = ramp(0.0, 300.0, 3000, false);
    let grid = ramp(0.0, 300.0, 600, false);
    for (range, lo, hi, _) in RANGES {
        let measured = wave(&measured_time, lo, hi, 0.0);
        let fits = vec![
            (
                "hx seed: objective 1.2000e-2".to_string(),
                grid.clone(),
                wave(&grid, lo, hi, 0.05),
            ),
            (
                "hx naive: objective 8.1000e-1".to_string(),
                grid.clone(),
                wave(&grid, lo, hi, 0.5),
            ),
        ];
        let svg = comparison_svg(
            "T_out: hx seed vs hx naive",
            "T_out [K]",
            (&measured_time, &measured),
            &fits,
            &[(10.0, 290.0)],
        );
        look("comparison", range, &svg);
        assert!(svg.contains("hx seed: objective") && svg.contains("hx naive: objective"));
    }
}

#[test]
fn a_legend_of_many_entries_moves_below_the_data_area() {
    let x = ramp(0.0, 1.0, 10, false);
    let runs: Vec<PlotSeries> = (0..60)
        .map(|r| {
            let y: Vec<f64> = x.iter().map(|v| v + r as f64).collect();
            series(&format!("differential-evolution #{}", r + 1), &x, &y)
        })
        .collect();
    let request = PlotRequest {
        series: runs,
        ..PlotRequest::default()
    };
    let svg = draw(&request).unwrap_or_else(|_| panic!("the plot is refused"));
    let a = look("legend", "many", &svg);
    let (data, legend) = (a.data_area.unwrap(), a.legend.unwrap());
    assert!(legend.y >= data.y + data.h, "{data:?} {legend:?}");
}
