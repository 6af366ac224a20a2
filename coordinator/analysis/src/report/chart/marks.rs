//! What is drawn in the data area: shaded ranges, bars with their whiskers, and the series
//! as lines (broken where a value is not finite, thinned to the pixels) or dots.

use super::{rgb, Bars, Plane, Series};
use std::fmt::Write;

/// The ranges of the abscissa to shade, clipped to the axis.
pub(super) fn shades(s: &mut String, shades: &[(f64, f64)], plane: &Plane) {
    for &(a, b) in shades {
        let (a, b) = (plane.px(a.max(plane.x.lo)), plane.px(b.min(plane.x.hi)));
        if a.is_finite() && b.is_finite() && b > a {
            let _ = write!(
                s,
                r#"<rect class="shade" x="{a:.1}" y="{:.1}" width="{:.1}" height="{:.1}" fill="rgb(235,242,250)"/>"#,
                plane.data.y,
                b - a,
                plane.data.h
            );
        }
    }
}

/// The bars, grouped per category, each with its interval as a whisker.
pub(super) fn bars(s: &mut String, bars: &[Bars], plane: &Plane) {
    if bars.is_empty() {
        return;
    }
    let zero = plane.py(if plane.y.log { plane.y.lo } else { 0.0 });
    let k = bars.len() as f64;
    let group = 0.8 / k;
    for (b, set) in bars.iter().enumerate() {
        for (i, &v) in set.values.iter().enumerate() {
            let x0 = plane.px(i as f64 + 1.0 - 0.4 + group * b as f64);
            let x1 = plane.px(i as f64 + 1.0 - 0.4 + group * (b as f64 + 1.0));
            let v = if v.is_finite() { v } else { 0.0 };
            let y = plane.py(v);
            if !y.is_finite() {
                continue;
            }
            let _ = write!(
                s,
                r#"<rect class="bar" x="{x0:.1}" y="{:.1}" width="{:.1}" height="{:.1}" fill="{}"/>"#,
                y.min(zero),
                x1 - x0,
                (zero - y).abs(),
                rgb(set.color)
            );
            if let Some(&(lo, hi)) = set.intervals.get(i) {
                let (a, b) = (plane.py(lo), plane.py(hi));
                if a.is_finite() && b.is_finite() {
                    let xm = (x0 + x1) / 2.0;
                    let _ = write!(
                        s,
                        r#"<line class="whisker" x1="{xm:.1}" y1="{a:.1}" x2="{xm:.1}" y2="{b:.1}" stroke="black"/>"#
                    );
                }
            }
        }
    }
}

/// The series in order (a later one drawn above an earlier one), clipped to the data area
/// by the clip path `clip`.
pub(super) fn series(s: &mut String, series: &[Series], plane: &Plane, clip: &str) {
    let _ = write!(s, r#"<g clip-path="url(#{clip})">"#);
    for one in series {
        draw(s, one, plane);
    }
    s.push_str("</g>");
}

/// One series: its dots, or its line in pieces between values that are not finite.
fn draw(s: &mut String, series: &Series, plane: &Plane) {
    let color = rgb(series.color);
    let points: Vec<Option<(f64, f64)>> = series
        .time
        .iter()
        .zip(series.values)
        .map(|(&t, &v)| {
            let p = (plane.px(t), plane.py(v));
            (p.0.is_finite() && p.1.is_finite()).then_some(p)
        })
        .collect();
    if let Some(radius) = series.dots {
        for (x, y) in points.iter().flatten() {
            let _ = write!(
                s,
                r#"<circle cx="{x:.1}" cy="{y:.1}" r="{radius}" fill="{color}"/>"#
            );
        }
        return;
    }
    let dash = series
        .dash
        .array()
        .map(|d| format!(r#" stroke-dasharray="{d}""#))
        .unwrap_or_default();
    for piece in points.split(|p| p.is_none()) {
        let piece: Vec<(f64, f64)> = piece.iter().flatten().copied().collect();
        if piece.is_empty() {
            continue;
        }
        let piece = thin(&piece, plane.data.w);
        s.push_str(r#"<polyline class="series" points=""#);
        for (i, (x, y)) in piece.iter().enumerate() {
            if i > 0 {
                s.push(' ');
            }
            let _ = write!(s, "{x:.1},{y:.1}");
        }
        let _ = write!(
            s,
            r#"" fill="none" stroke="{color}" stroke-width="{}" stroke-linejoin="round"{dash}/>"#,
            series.width
        );
    }
}

/// Points of a line in pixels, thinned to the first, lowest, highest and last point per
/// pixel column when there are many more points than columns.
fn thin(points: &[(f64, f64)], columns: f64) -> Vec<(f64, f64)> {
    if (points.len() as f64) < 4.0 * columns {
        return points.to_vec();
    }
    let mut out = Vec::new();
    let mut i = 0;
    while i < points.len() {
        let column = points[i].0.floor();
        let mut j = i;
        let (mut low, mut high) = (i, i);
        while j < points.len() && points[j].0.floor() == column {
            if points[j].1 < points[low].1 {
                low = j;
            }
            if points[j].1 > points[high].1 {
                high = j;
            }
            j += 1;
        }
        let mut keep = vec![i, low, high, j - 1];
        keep.sort_unstable();
        keep.dedup();
        out.extend(keep.into_iter().map(|k| points[k]));
        i = j;
    }
    out
}
