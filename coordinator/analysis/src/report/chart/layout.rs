//! Where the parts of a plot go: the title on top, the y ticks and label on the left, the x
//! ticks and label below, the legend right of the data area (with the direct labels between
//! them) or, when that would take more than a third of the width, below the x label, the
//! canvas growing rather than the data area shrinking below half of it.

use super::axis::Axis;
use super::legend::Entry;
use super::{text_width, Chart, Rect, FONT};

/// Height of a legend row [px].
pub(super) const ROW: f64 = 18.0;

/// The canvas and the places on it.
pub(super) struct Layout {
    /// The canvas (its height grown for a legend below the data area).
    pub(super) width: f64,
    pub(super) height: f64,
    pub(super) data: Rect,
    pub(super) legend: Rect,
    /// The legend is right of the data area (its entries filled column by column).
    pub(super) legend_right: bool,
    /// Width of one legend entry.
    pub(super) entry_width: f64,
    /// The x tick labels are turned (categories too long to stand side by side).
    pub(super) rotate: bool,
    /// Height the x tick labels take below the data area.
    pub(super) x_tick_height: f64,
}

/// What the axes take around the data area.
struct Margins {
    left: f64,
    top: f64,
    rotate: bool,
    x_tick_height: f64,
    /// Height of the x ticks and the x label together.
    bottom_axes: f64,
}

fn margins(chart: &Chart, x_axis: &Axis, y_axis: &Axis, width: f64) -> Margins {
    let y_tick_width = y_axis
        .ticks
        .labels
        .iter()
        .map(|l| text_width(l, FONT))
        .fold(0.0, f64::max);
    let left = 12.0 + 18.0 + y_tick_width + 10.0;
    let top = 34.0
        + if y_axis.ticks.note.is_some() {
            16.0
        } else {
            0.0
        };
    let rotate = !chart.categories.is_empty() && {
        let room = (width - left - 40.0) / x_axis.ticks.labels.len().max(1) as f64;
        x_axis
            .ticks
            .labels
            .iter()
            .any(|l| text_width(l, FONT) + 6.0 > room)
    };
    let x_tick_height = if rotate {
        x_axis
            .ticks
            .labels
            .iter()
            .map(|l| text_width(l, FONT) * 0.6)
            .fold(0.0, f64::max)
            + 18.0
    } else {
        20.0
    };
    let x_desc_height = if chart.x_label.is_empty() { 4.0 } else { 22.0 };
    Margins {
        left,
        top,
        rotate,
        x_tick_height,
        bottom_axes: x_tick_height + x_desc_height + 8.0,
    }
}

/// The layout of `chart` with these axes and legend `entries` on a canvas of `width` ×
/// `height`.
pub(super) fn place(
    chart: &Chart,
    x_axis: &Axis,
    y_axis: &Axis,
    entries: &[Entry],
    width: f64,
    height: f64,
) -> Layout {
    let m = margins(chart, x_axis, y_axis, width);
    let entry_width = entries
        .iter()
        .map(|e| text_width(&e.label, FONT))
        .fold(0.0, f64::max)
        + 40.0;
    let direct_width = if chart.direct_labels {
        chart
            .series
            .iter()
            .map(|s| text_width(s.label, 11.0))
            .fold(0.0, f64::max)
            + 12.0
    } else {
        0.0
    };
    let est_data_height = height - m.top - m.bottom_axes - 10.0;
    let fit_rows = ((est_data_height - 10.0) / ROW).floor().max(1.0) as usize;
    let right_columns = entries.len().div_ceil(fit_rows).max(1);
    let right_width = if entries.is_empty() {
        0.0
    } else {
        right_columns as f64 * entry_width + 12.0
    };
    let legend_right = entries.is_empty() || right_width <= 0.34 * width;
    let (legend, data, height) = if legend_right {
        let data_right =
            width - 12.0 - right_width - direct_width - if entries.is_empty() { 0.0 } else { 14.0 };
        let data = Rect {
            x: m.left,
            y: m.top,
            w: (data_right - m.left).max(50.0),
            h: (height - m.top - m.bottom_axes).max(50.0),
        };
        let rows = entries.len().min(fit_rows);
        let legend = Rect {
            x: data.x + data.w + direct_width + 14.0,
            y: m.top,
            w: right_width,
            h: rows as f64 * ROW + 10.0,
        };
        (legend, data, height)
    } else {
        below(&m, entries.len(), entry_width, direct_width, width, height)
    };
    Layout {
        width,
        height,
        data,
        legend,
        legend_right,
        entry_width,
        rotate: m.rotate,
        x_tick_height: m.x_tick_height,
    }
}

/// The legend of `entries` entries below the x label, in as many columns as fit, and the
/// data area above it: the legend, the data area and the canvas' height.
fn below(
    m: &Margins,
    entries: usize,
    entry_width: f64,
    direct_width: f64,
    width: f64,
    height: f64,
) -> (Rect, Rect, f64) {
    let mut height = height;
    let avail = width - m.left - 24.0;
    let columns = ((avail / entry_width).floor() as usize).clamp(1, entries);
    let rows = entries.div_ceil(columns);
    let legend_height = rows as f64 * ROW + 10.0;
    // The canvas grows rather than the data area shrinking below half of it.
    let needed = m.top + m.bottom_axes + legend_height + 12.0 + 0.5 * height;
    if needed > height {
        height = needed;
    }
    let data = Rect {
        x: m.left,
        y: m.top,
        w: width - m.left - 24.0 - direct_width,
        h: height - m.top - m.bottom_axes - legend_height - 12.0,
    };
    let legend = Rect {
        x: m.left,
        y: data.y + data.h + m.bottom_axes,
        w: columns as f64 * entry_width + 12.0,
        h: legend_height,
    };
    (legend, data, height)
}
