//! The web app's plots: SVG drawn by the report's plotting code
//! ([`crate::report::plot::line_plot_svg`]), the one code path of every plot calib draws.

use super::{ApiError, WebApp};
use crate::measurement::Measurement;
use crate::report::plot::{line_plot_svg, Series};
use axum::extract::{Path, State};
use axum::http::header;
use axum::response::{IntoResponse, Response};
use plotters::style::RGBColor;
use serde::Deserialize;
use tonic::Status;

/// Colours of successive series; the legend names each one, so a plot reads without them.
const PALETTE: [RGBColor; 8] = [
    RGBColor(38, 139, 210),
    RGBColor(220, 50, 47),
    RGBColor(133, 153, 0),
    RGBColor(108, 113, 196),
    RGBColor(181, 137, 0),
    RGBColor(42, 161, 152),
    RGBColor(211, 54, 130),
    RGBColor(88, 110, 117),
];

/// Most points drawn per series.
const MAX_POINTS: usize = 20_000;

/// What `POST /ui/plot` draws.
#[derive(Debug, Deserialize)]
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
}

/// One series; `null` values (an objective not known yet) are left out.
#[derive(Debug, Deserialize)]
pub struct PlotSeries {
    #[serde(default)]
    pub label: String,
    pub x: Vec<Option<f64>>,
    pub y: Vec<Option<f64>>,
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

/// The SVG of `request`.
pub fn draw(request: &PlotRequest) -> Result<String, ApiError> {
    let mut columns = Vec::with_capacity(request.series.len());
    for (i, s) in request.series.iter().enumerate() {
        if s.x.len() != s.y.len() {
            return Err(invalid(format!(
                "series[{i}]: {} abscissae for {} values",
                s.x.len(),
                s.y.len()
            )));
        }
        if s.x.len() > MAX_POINTS {
            return Err(invalid(format!(
                "series[{i}]: {} points, at most {MAX_POINTS} are drawn",
                s.x.len()
            )));
        }
        let x: Vec<f64> = s.x.iter().map(|v| v.unwrap_or(f64::NAN)).collect();
        let y: Vec<f64> = s.y.iter().map(|v| v.unwrap_or(f64::NAN)).collect();
        columns.push((x, y));
    }
    let series: Vec<Series> = request
        .series
        .iter()
        .zip(&columns)
        .enumerate()
        .map(|(i, (s, (x, y)))| Series {
            label: &s.label,
            time: x,
            values: y,
            color: PALETTE[i % PALETTE.len()],
            width: if i == 0 { 2 } else { 1 },
        })
        .collect();
    line_plot_svg(
        &request.title,
        &request.x_label,
        &request.y_label,
        &series,
        request.shade,
    )
    .map_err(|e| ApiError(Status::internal(format!("cannot draw the plot: {e}"))))
}

/// `POST /ui/plot`: series the page holds (a simulation, a campaign's progress) as SVG.
pub async fn plot(body: axum::body::Bytes) -> Result<Response, ApiError> {
    let request: PlotRequest = super::decode(&body)?;
    let text = tokio::task::spawn_blocking(move || draw(&request))
        .await
        .map_err(|e| ApiError(Status::internal(e.to_string())))??;
    Ok(svg(text))
}

/// `GET /ui/datasets/{id}/plot/{column}`: one column of an uploaded dataset over time.
pub async fn dataset_plot(
    State(app): State<WebApp>,
    Path((id, column)): Path<(String, String)>,
) -> Result<Response, ApiError> {
    let campaigns = app.campaigns.clone();
    let text = tokio::task::spawn_blocking(move || {
        let datasets = campaigns.datasets();
        let info = datasets
            .get(&id)
            .map_err(|e| invalid(e.to_string()))?
            .ok_or_else(|| ApiError(Status::not_found(format!("id: no dataset `{id}` here"))))?;
        let m = Measurement::load(&datasets.file(&info), &info.time_column, &[&column])
            .map_err(|e| invalid(format!("data: {e}")))?;
        let values = m.column(&column).unwrap_or(&[]);
        line_plot_svg(
            &format!("{}: {column}", info.file_name),
            &format!("{} [s]", info.time_column),
            &column,
            &[Series {
                label: "measured",
                time: &m.time,
                values,
                color: RGBColor(120, 120, 120),
                width: 1,
            }],
            None,
        )
        .map_err(|e| ApiError(Status::internal(format!("cannot draw the plot: {e}"))))
    })
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
        let datasets = campaigns.datasets();
        let info = datasets
            .get(&id)
            .map_err(|e| invalid(e.to_string()))?
            .ok_or_else(|| ApiError(Status::not_found(format!("id: no dataset `{id}` here"))))?;
        let m = Measurement::load(&datasets.file(&info), &info.time_column, &[&column])
            .map_err(|e| invalid(format!("data: {e}")))?;
        let values = m.column(&column).unwrap_or(&[]);
        Ok::<_, ApiError>(serde_json::json!({ "times": m.time, "values": values }).to_string())
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
            shade: None,
        };
        let svg = draw(&request).unwrap_or_else(|e| panic!("{}", e.0.message()));
        assert!(svg.starts_with("<svg") && svg.contains("best objective of each run"));
        assert!(svg.contains("run 1") && svg.contains("run 2"));
    }

    #[test]
    fn series_of_unequal_lengths_are_refused_naming_the_series() {
        let request = PlotRequest {
            title: String::new(),
            x_label: String::new(),
            y_label: String::new(),
            series: vec![
                series("ok", vec![Some(0.0)], vec![Some(1.0)]),
                series("bad", vec![Some(0.0), Some(1.0)], vec![Some(1.0)]),
            ],
            shade: None,
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
