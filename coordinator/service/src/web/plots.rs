//! The web app's plots: SVG drawn by the report's plotting code
//! ([`calib_analysis::report::plot::line_plot_svg`]), the one code path of every plot calib draws.

use super::{ApiError, WebApp};
use crate::hosting::datasets::DatasetInfo;
use crate::hosting::Campaigns;
use axum::extract::{Path, State};
use axum::http::header;
use axum::response::{IntoResponse, Response};
use calib_analysis::report::chart::{self, style, Chart, Dash, Scale};
use calib_analysis::report::plot::{
    comparison_svg, line_plot_svg, uniform_grid, with_unit, Series, MEASURED,
};
use calib_engine::campaign::Campaign;
use calib_engine::measurement::Measurement;
use calib_engine::outcome::CalibrationOutcome;
use calib_model::Run;
use serde::Deserialize;
use tonic::Status;

/// Most points drawn per series.
const MAX_POINTS: usize = 20_000;

/// Most series (overlays included) in one plot.
const MAX_SERIES: usize = 200;

/// Most campaigns in one comparison.
const MAX_COMPARED: usize = 8;

/// Points per simulated curve of a comparison.
const CURVE_POINTS: usize = 2000;

/// What `POST /ui/plot` draws.
#[derive(Debug, Default, Deserialize)]
pub struct PlotRequest {
    #[serde(default)]
    pub title: String,
    #[serde(default)]
    pub x_label: String,
    #[serde(default)]
    pub y_label: String,
    pub series: Vec<PlotSeries>,
    /// A range of the abscissa to shade (the fitted window).
    #[serde(default)]
    pub shade: Option<(f64, f64)>,
    /// `"linear"` (the default), `"log"`, or `"auto"`: log when the values are positive
    /// and span more than two decades.
    #[serde(default)]
    pub x_scale: String,
    #[serde(default)]
    pub y_scale: String,
    /// Earlier sets of series drawn under `series`, oldest first (a previous simulation
    /// under the new one): each in its series' colours, dashed, labelled
    /// `<set label>: <series label>`.
    #[serde(default)]
    pub overlays: Vec<SeriesSet>,
    /// Name each line at its end, right of the data area (many runs).
    #[serde(default)]
    pub direct_labels: bool,
}

/// One series; `null` values (an objective not known yet) are left out.
#[derive(Debug, Default, Deserialize)]
pub struct PlotSeries {
    #[serde(default)]
    pub label: String,
    pub x: Vec<Option<f64>>,
    pub y: Vec<Option<f64>>,
}

/// One set of series: a simulation, a campaign's fit.
#[derive(Debug, Default, Deserialize)]
pub struct SeriesSet {
    #[serde(default)]
    pub label: String,
    pub series: Vec<PlotSeries>,
}

fn svg(text: String) -> Response {
    (
        [
            (header::CONTENT_TYPE, "image/svg+xml"),
            (header::CACHE_CONTROL, "no-cache"),
        ],
        text,
    )
        .into_response()
}

fn invalid(message: String) -> ApiError {
    ApiError(Status::invalid_argument(message))
}

/// The abscissae and values of `s`, `null` as NaN, checked; `place` names it in errors.
fn columns(place: &str, s: &PlotSeries) -> Result<(Vec<f64>, Vec<f64>), ApiError> {
    if s.x.len() != s.y.len() {
        return Err(invalid(format!(
            "{place}: {} abscissae for {} values",
            s.x.len(),
            s.y.len()
        )));
    }
    if s.x.len() > MAX_POINTS {
        return Err(invalid(format!(
            "{place}: {} points, at most {MAX_POINTS} are drawn",
            s.x.len()
        )));
    }
    let x = s.x.iter().map(|v| v.unwrap_or(f64::NAN)).collect();
    let y = s.y.iter().map(|v| v.unwrap_or(f64::NAN)).collect();
    Ok((x, y))
}

fn scale(field: &str, text: &str) -> Result<Scale, ApiError> {
    Scale::parse(text).ok_or_else(|| {
        invalid(format!(
            "{field}: `{text}` is not a scale; use linear, log or auto"
        ))
    })
}

/// The SVG of `request`.
pub fn draw(request: &PlotRequest) -> Result<String, ApiError> {
    let x_scale = scale("x_scale", &request.x_scale)?;
    let y_scale = scale("y_scale", &request.y_scale)?;
    let count = request.series.len()
        + request
            .overlays
            .iter()
            .map(|o| o.series.len())
            .sum::<usize>();
    if count > MAX_SERIES {
        return Err(invalid(format!(
            "series: {count} series, at most {MAX_SERIES} are drawn"
        )));
    }
    // Overlays first (under the new series), each series in the colour of the new series
    // it stands for, dashed.
    let mut data = Vec::with_capacity(count);
    let mut labels = Vec::with_capacity(count);
    let mut looks = Vec::with_capacity(count);
    for (k, set) in request.overlays.iter().enumerate() {
        for (i, s) in set.series.iter().enumerate() {
            data.push(columns(&format!("overlays[{k}].series[{i}]"), s)?);
            labels.push(match (set.label.is_empty(), s.label.is_empty()) {
                (false, false) => format!("{}: {}", set.label, s.label),
                (false, true) => set.label.clone(),
                (true, _) => s.label.clone(),
            });
            let dash = [Dash::Dashed, Dash::Dotted, Dash::DashDot, Dash::LongDash]
                [(request.overlays.len() - 1 - k) % 4];
            looks.push((style(i).0, dash, 1));
        }
    }
    let many = request.series.len() > 4;
    for (i, s) in request.series.iter().enumerate() {
        data.push(columns(&format!("series[{i}]"), s)?);
        labels.push(s.label.clone());
        let (color, dash) = style(i);
        looks.push((color, dash, if many { 1 } else { 2 }));
    }
    let series: Vec<Series> = data
        .iter()
        .zip(&labels)
        .zip(&looks)
        .map(|(((x, y), label), &(color, dash, width))| {
            Series::new(label, x, y, color, width).dashed(dash)
        })
        .collect();
    let shades: Vec<(f64, f64)> = request.shade.into_iter().collect();
    Ok(chart::render(&Chart {
        title: &request.title,
        x_label: &request.x_label,
        y_label: &request.y_label,
        series: &series,
        shades: &shades,
        x_scale,
        y_scale,
        direct_labels: request.direct_labels,
        ..Chart::default()
    }))
}

/// `POST /ui/plot`: series the page holds (a simulation, a campaign's progress) as SVG.
pub async fn plot(body: axum::body::Bytes) -> Result<Response, ApiError> {
    let request: PlotRequest = super::decode(&body)?;
    let text = tokio::task::spawn_blocking(move || draw(&request))
        .await
        .map_err(|e| ApiError(Status::internal(e.to_string())))??;
    Ok(svg(text))
}

/// One column of an uploaded dataset, loaded with its times: what the dataset's plot and
/// its JSON column are both made of.
struct DatasetColumn {
    /// The dataset's description (its file name and time column title the plot).
    info: DatasetInfo,
    /// The column's name.
    column: String,
    /// The dataset's times and the one column.
    measurement: Measurement,
}

impl DatasetColumn {
    /// Load `column` of the dataset `id`; one place for the routes' errors (no such
    /// dataset, a file that does not load).
    fn load(campaigns: &Campaigns, id: &str, column: String) -> Result<Self, ApiError> {
        let datasets = campaigns.datasets();
        let info = datasets
            .get(id)
            .map_err(|e| invalid(e.to_string()))?
            .ok_or_else(|| ApiError(Status::not_found(format!("id: no dataset `{id}` here"))))?;
        let measurement = Measurement::load(&datasets.file(&info), &info.time_column, &[&column])
            .map_err(|e| invalid(format!("data: {e}")))?;
        Ok(Self {
            info,
            column,
            measurement,
        })
    }

    /// The column's values, none when the file lacks it.
    fn values(&self) -> &[f64] {
        self.measurement.column(&self.column).unwrap_or(&[])
    }
}

/// `GET /ui/datasets/{id}/plot/{column}`: one column of an uploaded dataset over time.
pub async fn dataset_plot(
    State(app): State<WebApp>,
    Path((id, column)): Path<(String, String)>,
) -> Result<Response, ApiError> {
    let campaigns = app.campaigns.clone();
    let text = tokio::task::spawn_blocking(move || {
        let loaded = DatasetColumn::load(&campaigns, &id, column)?;
        let (info, column) = (&loaded.info, &loaded.column);
        line_plot_svg(
            &format!("{}: {column}", info.file_name),
            &format!("{} [s]", info.time_column),
            column,
            &[Series::new(
                "measured",
                &loaded.measurement.time,
                loaded.values(),
                MEASURED,
                1,
            )],
            None,
        )
        .map_err(|e| ApiError(Status::internal(format!("cannot draw the plot: {e}"))))
    })
    .await
    .map_err(|e| ApiError(Status::internal(e.to_string())))??;
    Ok(svg(text))
}

/// What `POST /ui/compare` draws: the fits of one output by several finished campaigns.
#[derive(Debug, Default, Deserialize)]
pub struct CompareRequest {
    /// The campaigns' ids, two or more; the first one's measured data and fitted windows
    /// are drawn.
    pub campaigns: Vec<String>,
    /// A model output every campaign compares with measured data (`armJoint.phi`).
    pub output: String,
}

/// A finished campaign to compare (`place` names it in errors): the campaign, its name, its
/// outcome and the index of `output` among the outputs it compares.
fn compared(
    campaigns: &crate::hosting::Campaigns,
    place: &str,
    id: &str,
    output: &str,
) -> Result<(Campaign, String, CalibrationOutcome, usize), ApiError> {
    let public = |e: calib_engine::error::Error| campaigns.public(&e.to_string());
    let key = calib_engine::store::unhex32(id).ok_or_else(|| {
        ApiError(Status::not_found(format!(
            "{place}: no campaign `{id}` here"
        )))
    })?;
    let campaign: Campaign = campaigns
        .finished(&key, id, "compare")
        .map_err(|e| invalid(format!("{place}: {}", public(e))))?
        .ok_or_else(|| {
            ApiError(Status::not_found(format!(
                "{place}: no campaign `{id}` here"
            )))
        })?;
    let snapshot = campaigns
        .get(id)
        .map_err(|e| ApiError(Status::internal(public(e))))?
        .ok_or_else(|| {
            ApiError(Status::not_found(format!(
                "{place}: no campaign `{id}` here"
            )))
        })?;
    let result = snapshot
        .result
        .ok_or_else(|| invalid(format!("{place}: campaign `{id}` has no result to compare")))?;
    let Some(j) = campaign.outputs.iter().position(|o| o.model == output) else {
        let known: Vec<&str> = campaign.outputs.iter().map(|o| o.model.as_str()).collect();
        return Err(invalid(format!(
            "output: campaign {} does not compare `{}` with measured data (it compares {})",
            campaign.name,
            output,
            known.join(", ")
        )));
    };
    Ok((campaign, snapshot.name, result, j))
}

/// The measured data of `output` and each campaign's calibrated model of it, as SVG.
pub fn compare_svg(
    campaigns: &crate::hosting::Campaigns,
    request: &CompareRequest,
) -> Result<String, ApiError> {
    if request.campaigns.len() < 2 || request.campaigns.len() > MAX_COMPARED {
        return Err(invalid(format!(
            "campaigns: {} ids; a comparison takes 2 to {MAX_COMPARED}",
            request.campaigns.len()
        )));
    }
    let mut gathered = Comparison::default();
    for (k, id) in request.campaigns.iter().enumerate() {
        let place = format!("campaigns[{k}]");
        let (campaign, name, result, j) = compared(campaigns, &place, id, &request.output)?;
        let curve = Curve::of(campaigns, &place, &campaign, &result, j)?;
        if gathered.measured.is_none() {
            gathered.keep_measured(&campaign, &curve.measurement, j);
        }
        let label = gathered.label(name, id);
        let objective_value = result.best.objective;
        gathered.fits.push((
            format!("{label}: objective {objective_value:.4e}"),
            curve.grid,
            curve.values,
        ));
    }
    let Comparison {
        fits,
        measured,
        windows,
        unit,
        names,
    } = gathered;
    let (t, v) = measured.unwrap_or_default();
    Ok(comparison_svg(
        &format!("{}: {}", request.output, names.join(" vs ")),
        &with_unit(&request.output, &unit),
        (&t, &v),
        &fits,
        &windows,
    ))
}

/// What a comparison gathers campaign by campaign: each fit, with the first campaign's
/// measured data, fitted windows and output unit.
#[derive(Default)]
struct Comparison {
    /// Each campaign's label and its calibrated curve (times, values).
    fits: Vec<(String, Vec<f64>, Vec<f64>)>,
    /// The first campaign's measured data within its simulated span (times, values).
    measured: Option<(Vec<f64>, Vec<f64>)>,
    /// The first campaign's fitted windows.
    windows: Vec<(f64, f64)>,
    /// The unit of the compared output.
    unit: String,
    /// The campaigns' labels so far.
    names: Vec<String>,
}

impl Comparison {
    /// Keep the first campaign's measured data of output `j` within its simulated span, its
    /// windows and the output's unit: those the plot draws under every fit.
    fn keep_measured(&mut self, campaign: &Campaign, measurement: &Measurement, j: usize) {
        let o = &campaign.outputs[j];
        let column = measurement.column(&o.measured).unwrap_or(&[]);
        let shown: Vec<usize> = (0..measurement.time.len())
            .filter(|&i| {
                (campaign.solver.start_time..=campaign.stop_time).contains(&measurement.time[i])
            })
            .collect();
        self.measured = Some((
            shown.iter().map(|&i| measurement.time[i]).collect(),
            shown
                .iter()
                .filter_map(|&i| column.get(i).copied())
                .collect(),
        ));
        self.windows = campaign.windows.clone();
        self.unit = campaign.model.info().outputs[o.model_index].unit.clone();
    }

    /// The campaign's label, `name` with the start of its `id` when another campaign has
    /// that name already (the legend tells them apart); kept.
    fn label(&mut self, name: String, id: &str) -> String {
        let mut label = name;
        if self.names.contains(&label) {
            label = format!("{label} ({})", &id[..id.len().min(8)]);
        }
        self.names.push(label.clone());
        label
    }
}

/// A campaign's calibrated model of the compared output over its span, with the measured
/// data it was fitted to.
struct Curve {
    /// The campaign's measured data.
    measurement: Measurement,
    /// The times the curve is simulated at.
    grid: Vec<f64>,
    /// The output's simulated values at those times.
    values: Vec<f64>,
}

impl Curve {
    /// Simulate `campaign` at its best parameters (the nominal value of any the result
    /// lacks) and keep output `j`; `place` names the campaign in errors.
    fn of(
        campaigns: &Campaigns,
        place: &str,
        campaign: &Campaign,
        result: &CalibrationOutcome,
        j: usize,
    ) -> Result<Self, ApiError> {
        let public = |e: calib_engine::error::Error| campaigns.public(&e.to_string());
        let best = &result.best.parameters;
        let point: Vec<f64> = campaign
            .free
            .iter()
            .map(|p| best.get(&p.name).copied().unwrap_or(p.nominal))
            .collect();
        let measurement = calib_engine::calibration::load_measurement(campaign)
            .map_err(|e| invalid(format!("{place}: {}", public(e))))?;
        let objective = calib_engine::objective::Objective::new(campaign, &measurement)
            .map_err(|e| invalid(format!("{place}: {}", campaigns.public(&e.to_string()))))?;
        let grid = uniform_grid(campaign.solver.start_time, campaign.stop_time, CURVE_POINTS);
        let values = campaign
            .model
            .simulate(
                &Run::new(
                    &objective.full_parameters(&point),
                    &grid,
                    &objective.outputs,
                    &objective.solver,
                )
                .driven(&objective.inputs),
            )
            .map(|t| t.values.into_iter().nth(j).unwrap_or_default())
            .map_err(|e| {
                invalid(format!(
                    "{place}: the calibrated model does not simulate: {e}"
                ))
            })?;
        Ok(Self {
            measurement,
            grid,
            values,
        })
    }
}

/// `POST /ui/compare`: the fits of one output by two or more finished campaigns over the
/// measured data, as SVG ([`CompareRequest`]).
pub async fn compare(
    State(app): State<WebApp>,
    body: axum::body::Bytes,
) -> Result<Response, ApiError> {
    let request: CompareRequest = super::decode(&body)?;
    let campaigns = app.campaigns.clone();
    let text = tokio::task::spawn_blocking(move || compare_svg(&campaigns, &request))
        .await
        .map_err(|e| ApiError(Status::internal(e.to_string())))??;
    Ok(svg(text))
}

/// `GET /ui/datasets/{id}/column/{column}`: one column of an uploaded dataset and its times,
/// as JSON `{"times": [...], "values": [...]}` (a signal to drive a model's input with).
pub async fn dataset_column(
    State(app): State<WebApp>,
    Path((id, column)): Path<(String, String)>,
) -> Result<Response, ApiError> {
    let campaigns = app.campaigns.clone();
    let body = tokio::task::spawn_blocking(move || {
        let loaded = DatasetColumn::load(&campaigns, &id, column)?;
        let values = loaded.values();
        Ok::<_, ApiError>(
            serde_json::json!({ "times": loaded.measurement.time, "values": values }).to_string(),
        )
    })
    .await
    .map_err(|e| ApiError(Status::internal(e.to_string())))??;
    Ok((
        [
            (header::CONTENT_TYPE, "application/json"),
            (header::CACHE_CONTROL, "no-cache"),
        ],
        body,
    )
        .into_response())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn series(label: &str, x: Vec<Option<f64>>, y: Vec<Option<f64>>) -> PlotSeries {
        PlotSeries {
            label: label.into(),
            x,
            y,
        }
    }

    #[test]
    fn a_plot_names_its_series_and_leaves_unknown_values_out() {
        let request = PlotRequest {
            title: "best objective of each run".into(),
            x_label: "evaluations".into(),
            y_label: "objective".into(),
            series: vec![
                series("run 1", vec![Some(1.0), Some(2.0)], vec![None, Some(3.0)]),
                series(
                    "run 2",
                    vec![Some(1.0), Some(2.0)],
                    vec![Some(5.0), Some(4.0)],
                ),
            ],
            ..PlotRequest::default()
        };
        let svg = draw(&request).unwrap_or_else(|e| panic!("{}", e.0.message()));
        assert!(svg.starts_with("<svg") && svg.contains("best objective of each run"));
        assert!(svg.contains("run 1") && svg.contains("run 2"));
    }

    #[test]
    fn series_of_unequal_lengths_are_refused_naming_the_series() {
        let request = PlotRequest {
            series: vec![
                series("ok", vec![Some(0.0)], vec![Some(1.0)]),
                series("bad", vec![Some(0.0), Some(1.0)], vec![Some(1.0)]),
            ],
            ..PlotRequest::default()
        };
        let refused = draw(&request).expect_err("refused");
        assert_eq!(refused.0.code(), tonic::Code::InvalidArgument);
        assert!(
            refused.0.message().starts_with("series[1]:"),
            "{}",
            refused.0.message()
        );
    }
}
