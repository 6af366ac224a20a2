//! The axes of a plot: the range and scale of each (from the data, or the categories),
//! their ticks from [`super::super::ticks`], and how they are drawn: grid lines, tick marks
//! and labels, minor marks on a log axis, the note of a shared factor, the axis label.

use super::super::ticks::{self, Ticks};
use super::{escape, Chart, Plane, Scale, FONT};
use std::fmt::Write;

/// One axis: its range, scale and ticks.
pub(super) struct Axis {
    pub(super) lo: f64,
    pub(super) hi: f64,
    pub(super) log: bool,
    pub(super) ticks: Ticks,
}

impl Axis {
    /// The fraction of the axis' length at which `v` lies (not finite off a log axis' domain).
    pub(super) fn fraction(&self, v: f64) -> f64 {
        if self.log {
            if v <= 0.0 {
                return f64::NAN;
            }
            (v.log10() - self.lo.log10()) / (self.hi.log10() - self.lo.log10())
        } else {
            (v - self.lo) / (self.hi - self.lo)
        }
    }
}

/// The finite range of `values` (positive ones only when `positive`).
fn range<'b>(values: impl Iterator<Item = &'b f64>, positive: bool) -> Option<(f64, f64)> {
    let mut lo = f64::INFINITY;
    let mut hi = f64::NEG_INFINITY;
    for &v in values {
        if v.is_finite() && (!positive || v > 0.0) {
            lo = lo.min(v);
            hi = hi.max(v);
        }
    }
    (lo <= hi).then_some((lo, hi))
}

/// The axis over data `[lo, hi]` (`all_positive`: no value is ≤ 0), padded by `pad` of its
/// span on each side.
fn axis(
    scale: Scale,
    data: Option<(f64, f64)>,
    all_positive: bool,
    pad: f64,
    target: usize,
) -> Axis {
    let log = match scale {
        Scale::Linear => false,
        Scale::Log => data.is_some_and(|(lo, _)| lo > 0.0),
        Scale::Auto => all_positive && data.is_some_and(|(lo, hi)| ticks::spans_decades(lo, hi)),
    };
    let (lo, hi) = data.unwrap_or((0.0, 1.0));
    if log {
        let (a, b) = (lo.log10(), hi.log10());
        let span = (b - a).max(0.2);
        let (a, b) = (a - pad * span, b + pad * span);
        let (lo, hi) = (10f64.powf(a), 10f64.powf(b));
        Axis {
            lo,
            hi,
            log: true,
            ticks: ticks::log(lo, hi),
        }
    } else {
        let (lo, hi) = ticks::widen(lo, hi);
        let span = hi - lo;
        let (lo, hi) = (lo - pad * span, hi + pad * span);
        Axis {
            lo,
            hi,
            log: false,
            ticks: ticks::linear(lo, hi, target),
        }
    }
}

/// The abscissa: the categories at 1, 2, … when the chart names them, else the range of the
/// series' times where their values are finite.
pub(super) fn x_axis(chart: &Chart) -> Axis {
    if !chart.categories.is_empty() {
        return categories(chart.categories);
    }
    let xs = chart.series.iter().flat_map(|s| {
        s.time
            .iter()
            .zip(s.values)
            .filter(|(_, v)| v.is_finite())
            .map(|(t, _)| t)
    });
    let x_data = range(xs, false);
    let x_positive = chart
        .series
        .iter()
        .flat_map(|s| s.time.iter())
        .all(|v| !v.is_finite() || *v > 0.0);
    axis(chart.x_scale, x_data, x_positive, 0.0, 9)
}

/// An axis naming `categories` at 1, 2, …, at most 40 of them.
fn categories(categories: &[String]) -> Axis {
    let n = categories.len();
    let every = n.div_ceil(40).max(1);
    let values: Vec<f64> = (1..=n).step_by(every).map(|k| k as f64).collect();
    let labels = (1..=n)
        .step_by(every)
        .map(|k| categories[k - 1].clone())
        .collect();
    Axis {
        lo: 0.5,
        hi: n.max(1) as f64 + 0.5,
        log: false,
        ticks: Ticks {
            values,
            labels,
            note: None,
        },
    }
}

/// The ordinate: the range of the series' values at finite times, of the bars and their
/// intervals, and 0 under bars.
pub(super) fn y_axis(chart: &Chart) -> Axis {
    let bar_values = chart.bars.iter().flat_map(|b| {
        b.values
            .iter()
            .chain(b.intervals.iter().flat_map(|(lo, hi)| [lo, hi]))
    });
    let ys: Vec<f64> = chart
        .series
        .iter()
        .flat_map(|s| {
            s.time
                .iter()
                .zip(s.values)
                .filter(|(t, _)| t.is_finite())
                .map(|(_, v)| *v)
        })
        .chain(bar_values.copied())
        .chain(if chart.bars.is_empty() {
            None
        } else {
            Some(0.0)
        })
        .collect();
    let y_positive = ys.iter().all(|v| !v.is_finite() || *v > 0.0);
    let log_y =
        matches!(chart.y_scale, Scale::Log) || matches!(chart.y_scale, Scale::Auto) && y_positive;
    let y_data = range(ys.iter(), log_y).or_else(|| range(ys.iter(), false));
    axis(chart.y_scale, y_data, y_positive, 0.05, 6)
}

/// The x axis: a grid line, a mark and a label per tick (turned by 35° when `rotate`), minor
/// marks on a log axis, the note of a shared factor and `x_label` below the ticks, which
/// take `x_tick_height`.
pub(super) fn draw_x(
    s: &mut String,
    plane: &Plane,
    x_label: &str,
    rotate: bool,
    x_tick_height: f64,
) {
    let _ = write!(
        s,
        r#"<g class="axis-x" data-scale="{}">"#,
        if plane.x.log { "log" } else { "linear" }
    );
    for (v, label) in plane.x.ticks.values.iter().zip(&plane.x.ticks.labels) {
        let x = plane.px(*v);
        let _ = write!(
            s,
            r##"<line x1="{x:.1}" y1="{:.1}" x2="{x:.1}" y2="{:.1}" stroke="#ececec"/><line x1="{x:.1}" y1="{:.1}" x2="{x:.1}" y2="{:.1}" stroke="#444"/>"##,
            plane.data.y,
            plane.data.y + plane.data.h,
            plane.data.y + plane.data.h,
            plane.data.y + plane.data.h + 5.0
        );
        if rotate {
            let y = plane.data.y + plane.data.h + 12.0;
            let _ = write!(
                s,
                r#"<text class="tick-x" x="{x:.1}" y="{y:.1}" font-size="{FONT}" text-anchor="end" transform="rotate(-35 {x:.1} {y:.1})">{}</text>"#,
                escape(label)
            );
        } else {
            let _ = write!(
                s,
                r#"<text class="tick-x" x="{x:.1}" y="{:.1}" font-size="{FONT}" text-anchor="middle">{}</text>"#,
                plane.data.y + plane.data.h + 18.0,
                escape(label)
            );
        }
    }
    if plane.x.log {
        minor_ticks(s, &plane.x, |v| {
            let x = plane.px(v);
            format!(
                r##"<line x1="{x:.1}" y1="{:.1}" x2="{x:.1}" y2="{:.1}" stroke="#444"/>"##,
                plane.data.y + plane.data.h,
                plane.data.y + plane.data.h + 3.0
            )
        });
    }
    if let Some(note) = &plane.x.ticks.note {
        let _ = write!(
            s,
            r#"<text class="axis-note-x" x="{:.1}" y="{:.1}" font-size="{FONT}" text-anchor="end">{}</text>"#,
            plane.data.x + plane.data.w,
            plane.data.y + plane.data.h + x_tick_height + 16.0,
            escape(note)
        );
    }
    if !x_label.is_empty() {
        let _ = write!(
            s,
            r#"<text class="axis-label-x" x="{:.1}" y="{:.1}" font-size="13" text-anchor="middle">{}</text>"#,
            plane.data.x + plane.data.w / 2.0,
            plane.data.y + plane.data.h + x_tick_height + 16.0,
            escape(x_label)
        );
    }
    s.push_str("</g>");
}

/// The y axis: a grid line, a mark and a label per tick, minor marks on a log axis, the
/// note of a shared factor above and `y_label` turned along the axis.
pub(super) fn draw_y(s: &mut String, plane: &Plane, y_label: &str) {
    let _ = write!(
        s,
        r#"<g class="axis-y" data-scale="{}">"#,
        if plane.y.log { "log" } else { "linear" }
    );
    for (v, label) in plane.y.ticks.values.iter().zip(&plane.y.ticks.labels) {
        let y = plane.py(*v);
        let _ = write!(
            s,
            r##"<line x1="{:.1}" y1="{y:.1}" x2="{:.1}" y2="{y:.1}" stroke="#ececec"/><line x1="{:.1}" y1="{y:.1}" x2="{:.1}" y2="{y:.1}" stroke="#444"/>"##,
            plane.data.x,
            plane.data.x + plane.data.w,
            plane.data.x - 5.0,
            plane.data.x
        );
        let _ = write!(
            s,
            r#"<text class="tick-y" x="{:.1}" y="{:.1}" font-size="{FONT}" text-anchor="end">{}</text>"#,
            plane.data.x - 8.0,
            y + 4.0,
            escape(label)
        );
    }
    if plane.y.log {
        minor_ticks(s, &plane.y, |v| {
            let y = plane.py(v);
            format!(
                r##"<line x1="{:.1}" y1="{y:.1}" x2="{:.1}" y2="{y:.1}" stroke="#444"/>"##,
                plane.data.x - 3.0,
                plane.data.x
            )
        });
    }
    if let Some(note) = &plane.y.ticks.note {
        let _ = write!(
            s,
            r#"<text class="axis-note-y" x="{:.1}" y="{:.1}" font-size="{FONT}" text-anchor="start">{}</text>"#,
            plane.data.x,
            plane.data.y - 6.0,
            escape(note)
        );
    }
    if !y_label.is_empty() {
        let (x, y) = (16.0, plane.data.y + plane.data.h / 2.0);
        let _ = write!(
            s,
            r#"<text class="axis-label-y" x="{x:.1}" y="{y:.1}" font-size="13" text-anchor="middle" transform="rotate(-90 {x:.1} {y:.1})">{}</text>"#,
            escape(y_label)
        );
    }
    s.push_str("</g>");
}

/// Short marks at 2…9 times each decade of a log axis.
fn minor_ticks(s: &mut String, axis: &Axis, mark: impl Fn(f64) -> String) {
    if axis.ticks.note.is_some() || axis.hi / axis.lo > 1e9 {
        return;
    }
    let (k0, k1) = (
        axis.lo.log10().floor() as i32,
        axis.hi.log10().ceil() as i32,
    );
    for k in k0..=k1 {
        for m in 2..=9 {
            let v = m as f64 * 10f64.powi(k);
            if v > axis.lo && v < axis.hi {
                s.push_str(&mark(v));
            }
        }
    }
}
