//! The legend: one entry per bar set and labelled series, in a bordered box beside or
//! below the data area; and the direct labels, each at the end of its line.

use super::{escape, rgb, Chart, Dash, Plane, RGBColor, Rect, Series, FONT};
use std::fmt::Write;

/// An entry of the legend.
pub(super) struct Entry {
    pub(super) label: String,
    color: RGBColor,
    dash: Dash,
    width: u32,
    kind: EntryKind,
}

enum EntryKind {
    Line,
    Dot,
    Bar,
}

/// The legend's entries: the bar sets, then the series with a label.
pub(super) fn entries(chart: &Chart) -> Vec<Entry> {
    let mut entries: Vec<Entry> = chart
        .bars
        .iter()
        .map(|b| Entry {
            label: b.label.to_string(),
            color: b.color,
            dash: Dash::Solid,
            width: 1,
            kind: EntryKind::Bar,
        })
        .collect();
    entries.extend(
        chart
            .series
            .iter()
            .filter(|s| !s.label.is_empty())
            .map(|s| Entry {
                label: s.label.to_string(),
                color: s.color,
                dash: s.dash,
                width: s.width,
                kind: if s.dots.is_some() {
                    EntryKind::Dot
                } else {
                    EntryKind::Line
                },
            }),
    );
    entries
}

/// The legend: a bordered box of entries in columns (filled column by column when
/// `rows_per_column` is given, else row by row).
pub(super) fn draw(
    s: &mut String,
    entries: &[Entry],
    rect: &Rect,
    entry_width: f64,
    row: f64,
    rows_per_column: Option<usize>,
) {
    let _ = write!(
        s,
        r##"<g class="legend"><rect class="legend-box" x="{:.1}" y="{:.1}" width="{:.1}" height="{:.1}" fill="white" stroke="#444"/>"##,
        rect.x, rect.y, rect.w, rect.h
    );
    let columns = ((rect.w - 12.0) / entry_width).round().max(1.0) as usize;
    for (i, e) in entries.iter().enumerate() {
        let (column, r) = match rows_per_column {
            Some(rows) => (i / rows.max(1), i % rows.max(1)),
            None => (i % columns, i / columns),
        };
        let x = rect.x + 8.0 + column as f64 * entry_width;
        let y = rect.y + 5.0 + r as f64 * row + row / 2.0;
        let color = rgb(e.color);
        match e.kind {
            EntryKind::Line => {
                let dash = e
                    .dash
                    .array()
                    .map(|d| format!(r#" stroke-dasharray="{d}""#))
                    .unwrap_or_default();
                let _ = write!(
                    s,
                    r#"<line x1="{x:.1}" y1="{y:.1}" x2="{:.1}" y2="{y:.1}" stroke="{color}" stroke-width="{}"{dash}/>"#,
                    x + 24.0,
                    e.width.max(1)
                );
            }
            EntryKind::Dot => {
                let _ = write!(
                    s,
                    r#"<circle cx="{:.1}" cy="{y:.1}" r="5" fill="{color}"/>"#,
                    x + 12.0
                );
            }
            EntryKind::Bar => {
                let _ = write!(
                    s,
                    r#"<rect x="{:.1}" y="{:.1}" width="14" height="10" fill="{color}"/>"#,
                    x + 5.0,
                    y - 5.0
                );
            }
        }
        let _ = write!(
            s,
            r#"<text x="{:.1}" y="{:.1}" font-size="{FONT}">{}</text>"#,
            x + 30.0,
            y + 4.0,
            escape(&e.label)
        );
    }
    s.push_str("</g>");
}

/// Each labelled line's label right of the data area at the height its line ends, pushed
/// apart so that none overlaps another.
pub(super) fn direct_labels(s: &mut String, chart: &Chart, plane: &Plane) {
    let data = &plane.data;
    let mut ends: Vec<(f64, &Series)> = chart
        .series
        .iter()
        .filter(|series| !series.label.is_empty())
        .filter_map(|series| {
            series
                .time
                .iter()
                .zip(series.values)
                .rev()
                .map(|(&t, &v)| (plane.px(t), plane.py(v)))
                .find(|(x, y)| x.is_finite() && y.is_finite())
                .map(|(_, y)| (y.clamp(data.y, data.y + data.h), series))
        })
        .collect();
    ends.sort_by(|a, b| a.0.total_cmp(&b.0));
    let gap = 12.0;
    let mut placed: Vec<f64> = Vec::with_capacity(ends.len());
    for (y, _) in &ends {
        let y = placed.last().map_or(*y, |last| y.max(last + gap));
        placed.push(y);
    }
    // Pushed below the data area: shift the whole column up.
    if let Some(&last) = placed.last() {
        let over = last - (data.y + data.h + 20.0);
        if over > 0.0 {
            for y in &mut placed {
                *y -= over;
            }
        }
    }
    for ((_, series), y) in ends.iter().zip(placed) {
        let _ = write!(
            s,
            r#"<text class="direct-label" x="{:.1}" y="{:.1}" font-size="11" fill="{}">{}</text>"#,
            data.x + data.w + 6.0,
            y + 4.0,
            rgb(series.color),
            escape(series.label)
        );
    }
}
