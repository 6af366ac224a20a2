//! The SVG every plot of calib is drawn as: a data area with ticks from [`super::ticks`]
//! (linear or log, chosen by the caller or by the data), shaded ranges, lines, dots and
//! bars, and the legend beside the data area (to its right, or below it when it would be
//! too wide) so that it never covers a curve. Written by hand rather than through a
//! plotting crate so that every tick, label and box is placed by rules the tests can check:
//! the data area is the `rect` of class `data-area`, the legend box the `rect` of class
//! `legend-box`, tick labels `text` of class `tick-x` / `tick-y`, the scale of an axis the
//! `data-scale` of its `g` of class `axis-x` / `axis-y`.

use super::ticks::{self, Ticks};
use std::fmt::Write;

/// How an axis maps values.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Scale {
    #[default]
    Linear,
    Log,
    /// Log when the values are all positive and span more than two decades.
    Auto,
}

impl Scale {
    /// `"linear"`, `"log"` or `"auto"`; `None` for anything else.
    pub fn parse(text: &str) -> Option<Scale> {
        match text {
            "linear" | "" => Some(Scale::Linear),
            "log" => Some(Scale::Log),
            "auto" => Some(Scale::Auto),
            _ => None,
        }
    }
}

/// A line's dash pattern.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Dash {
    #[default]
    Solid,
    Dashed,
    Dotted,
    DashDot,
    LongDash,
}

impl Dash {
    fn array(self) -> Option<&'static str> {
        match self {
            Dash::Solid => None,
            Dash::Dashed => Some("6 4"),
            Dash::Dotted => Some("1.5 3"),
            Dash::DashDot => Some("8 3 2 3"),
            Dash::LongDash => Some("14 5"),
        }
    }
}

/// One series of a plot: a line through its points (broken where a value is not finite),
/// or dots.
#[derive(Debug, Clone)]
pub struct Series<'a> {
    /// Its legend entry; an empty label keeps it out of the legend.
    pub label: &'a str,
    /// Abscissae (times for a time plot).
    pub time: &'a [f64],
    pub values: &'a [f64],
    pub color: RGBColor,
    pub width: u32,
    pub dash: Dash,
    /// Dots of this radius at each point instead of a line.
    pub dots: Option<f64>,
}

impl<'a> Series<'a> {
    /// A solid line.
    pub fn new(
        label: &'a str,
        time: &'a [f64],
        values: &'a [f64],
        color: RGBColor,
        width: u32,
    ) -> Self {
        Self {
            label,
            time,
            values,
            color,
            width,
            dash: Dash::Solid,
            dots: None,
        }
    }

    pub fn dashed(mut self, dash: Dash) -> Self {
        self.dash = dash;
        self
    }

    pub fn dots(mut self, radius: f64) -> Self {
        self.dots = Some(radius);
        self
    }
}

/// A colour of the charts, as 8-bit red, green and blue.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RGBColor(pub u8, pub u8, pub u8);

/// Colours of successive series (runs, campaigns).
pub const PALETTE: [RGBColor; 10] = [
    RGBColor(38, 139, 210),
    RGBColor(220, 50, 47),
    RGBColor(133, 153, 0),
    RGBColor(108, 113, 196),
    RGBColor(181, 137, 0),
    RGBColor(42, 161, 152),
    RGBColor(211, 54, 130),
    RGBColor(88, 110, 117),
    RGBColor(203, 75, 22),
    RGBColor(0, 0, 0),
];

/// The look of the `i`-th of several series: the palette's colours, then again with each of
/// four dash patterns, so that 50 series differ before a look repeats (the legend and the
/// direct labels name every one).
pub fn style(i: usize) -> (RGBColor, Dash) {
    const DASHES: [Dash; 5] = [
        Dash::Solid,
        Dash::Dashed,
        Dash::Dotted,
        Dash::DashDot,
        Dash::LongDash,
    ];
    (
        PALETTE[i % PALETTE.len()],
        DASHES[(i / PALETTE.len()) % DASHES.len()],
    )
}

/// Bars over categories, one group per category, with optional intervals (whiskers).
#[derive(Debug, Clone)]
pub struct Bars<'a> {
    pub label: &'a str,
    pub values: &'a [f64],
    pub intervals: &'a [(f64, f64)],
    pub color: RGBColor,
}

/// What to draw.
#[derive(Debug, Clone, Default)]
pub struct Chart<'a> {
    pub title: &'a str,
    pub x_label: &'a str,
    pub y_label: &'a str,
    pub series: &'a [Series<'a>],
    /// Ranges of the abscissa to shade (fitted windows, intervals).
    pub shades: &'a [(f64, f64)],
    pub x_scale: Scale,
    pub y_scale: Scale,
    /// Names of the categories at abscissae 1, 2, … (the runs of a waterfall, the
    /// parameters of a bar chart): the x ticks then name them.
    pub categories: &'a [String],
    pub bars: &'a [Bars<'a>],
    /// Labels at the end of each labelled line, in the margin right of the data area.
    pub direct_labels: bool,
    /// Width and height in pixels (1000 × 500 when zero).
    pub size: (u32, u32),
}

const FONT: f64 = 12.0;

/// Width of `text` in pixels at the tick font, estimated (no font metrics here).
fn text_width(text: &str, size: f64) -> f64 {
    text.chars().count() as f64 * size * 0.58
}

fn escape(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    for c in text.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            _ => out.push(c),
        }
    }
    out
}

fn rgb(c: RGBColor) -> String {
    format!("rgb({},{},{})", c.0, c.1, c.2)
}

/// One axis: its range, scale and ticks.
struct Axis {
    lo: f64,
    hi: f64,
    log: bool,
    ticks: Ticks,
}

impl Axis {
    /// The fraction of the axis' length at which `v` lies (not finite off a log axis' domain).
    fn fraction(&self, v: f64) -> f64 {
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

/// A rectangle: left, top, width, height.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Rect {
    pub x: f64,
    pub y: f64,
    pub w: f64,
    pub h: f64,
}

impl Rect {
    /// Whether the two overlap (touching edges do not).
    pub fn intersects(&self, other: &Rect) -> bool {
        self.x < other.x + other.w
            && other.x < self.x + self.w
            && self.y < other.y + other.h
            && other.y < self.y + self.h
    }
}

/// An entry of the legend.
struct Entry {
    label: String,
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

/// A short stable name for the clip path of a plot, so that several plots inlined in one
/// page do not share one.
fn clip_id(chart: &Chart) -> String {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    let mut eat = |bytes: &[u8]| {
        for b in bytes {
            h ^= *b as u64;
            h = h.wrapping_mul(0x0100_0000_01b3);
        }
    };
    eat(chart.title.as_bytes());
    eat(chart.y_label.as_bytes());
    for s in chart.series {
        eat(s.label.as_bytes());
        eat(&s.values.len().to_le_bytes());
        for v in s.values.iter().take(16) {
            eat(&v.to_le_bytes());
        }
    }
    format!("data-{h:016x}")
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

/// The SVG text of `chart`.
pub fn render(chart: &Chart) -> String {
    let (width, height) = if chart.size.0 == 0 {
        (1000.0, 500.0)
    } else {
        (chart.size.0 as f64, chart.size.1 as f64)
    };
    let categorical = !chart.categories.is_empty();
    // Ranges of the data.
    let xs = chart.series.iter().flat_map(|s| {
        s.time
            .iter()
            .zip(s.values)
            .filter(|(_, v)| v.is_finite())
            .map(|(t, _)| t)
    });
    let x_data = if categorical {
        Some((0.5, chart.categories.len() as f64 + 0.5))
    } else {
        range(xs, false)
    };
    let x_positive = chart
        .series
        .iter()
        .flat_map(|s| s.time.iter())
        .all(|v| !v.is_finite() || *v > 0.0);
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
    let x_axis = if categorical {
        let n = chart.categories.len();
        let every = n.div_ceil(40).max(1);
        let values: Vec<f64> = (1..=n).step_by(every).map(|k| k as f64).collect();
        let labels = (1..=n)
            .step_by(every)
            .map(|k| chart.categories[k - 1].clone())
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
    } else {
        axis(chart.x_scale, x_data, x_positive, 0.0, 9)
    };
    let y_axis = axis(chart.y_scale, y_data, y_positive, 0.05, 6);

    // The legend's entries.
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

    // Layout: title on top, y ticks and label on the left, x ticks and label below, legend
    // right of the data area or below the x label.
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
    let rotate = categorical && {
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
    let bottom_axes = x_tick_height + x_desc_height + 8.0;
    let row = 18.0;
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
    let mut height = height;
    let est_data_height = height - top - bottom_axes - 10.0;
    let fit_rows = ((est_data_height - 10.0) / row).floor().max(1.0) as usize;
    let right_columns = entries.len().div_ceil(fit_rows).max(1);
    let right_width = if entries.is_empty() {
        0.0
    } else {
        right_columns as f64 * entry_width + 12.0
    };
    let legend_right = entries.is_empty() || right_width <= 0.34 * width;
    let (legend, data) = if legend_right {
        let data_right =
            width - 12.0 - right_width - direct_width - if entries.is_empty() { 0.0 } else { 14.0 };
        let data = Rect {
            x: left,
            y: top,
            w: (data_right - left).max(50.0),
            h: (height - top - bottom_axes).max(50.0),
        };
        let rows = entries.len().min(fit_rows);
        let legend = Rect {
            x: data.x + data.w + direct_width + 14.0,
            y: top,
            w: right_width,
            h: rows as f64 * row + 10.0,
        };
        (legend, data)
    } else {
        let avail = width - left - 24.0;
        let columns = ((avail / entry_width).floor() as usize).clamp(1, entries.len());
        let rows = entries.len().div_ceil(columns);
        let legend_height = rows as f64 * row + 10.0;
        // The canvas grows rather than the data area shrinking below half of it.
        let needed = top + bottom_axes + legend_height + 12.0 + 0.5 * height;
        if needed > height {
            height = needed;
        }
        let data = Rect {
            x: left,
            y: top,
            w: width - left - 24.0 - direct_width,
            h: height - top - bottom_axes - legend_height - 12.0,
        };
        let legend = Rect {
            x: left,
            y: data.y + data.h + bottom_axes,
            w: columns as f64 * entry_width + 12.0,
            h: legend_height,
        };
        (legend, data)
    };
    let px = |v: f64| data.x + x_axis.fraction(v) * data.w;
    let py = |v: f64| data.y + data.h - y_axis.fraction(v) * data.h;

    let mut s = String::new();
    let _ = write!(
        s,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{height}" viewBox="0 0 {width} {height}" font-family="sans-serif">"#
    );
    let _ = write!(
        s,
        r#"<rect x="0" y="0" width="{width}" height="{height}" fill="white"/>"#
    );
    let _ = write!(
        s,
        r#"<text class="title" x="{:.1}" y="22" font-size="16" text-anchor="middle">{}</text>"#,
        width / 2.0,
        escape(chart.title)
    );
    let clip = clip_id(chart);
    let _ = write!(
        s,
        r#"<defs><clipPath id="{clip}"><rect x="{:.1}" y="{:.1}" width="{:.1}" height="{:.1}"/></clipPath></defs>"#,
        data.x, data.y, data.w, data.h
    );
    // Shaded ranges.
    for &(a, b) in chart.shades {
        let (a, b) = (px(a.max(x_axis.lo)), px(b.min(x_axis.hi)));
        if a.is_finite() && b.is_finite() && b > a {
            let _ = write!(
                s,
                r#"<rect class="shade" x="{a:.1}" y="{:.1}" width="{:.1}" height="{:.1}" fill="rgb(235,242,250)"/>"#,
                data.y,
                b - a,
                data.h
            );
        }
    }
    // Grid lines and ticks.
    let _ = write!(
        s,
        r#"<g class="axis-x" data-scale="{}">"#,
        if x_axis.log { "log" } else { "linear" }
    );
    for (v, label) in x_axis.ticks.values.iter().zip(&x_axis.ticks.labels) {
        let x = px(*v);
        let _ = write!(
            s,
            r##"<line x1="{x:.1}" y1="{:.1}" x2="{x:.1}" y2="{:.1}" stroke="#ececec"/><line x1="{x:.1}" y1="{:.1}" x2="{x:.1}" y2="{:.1}" stroke="#444"/>"##,
            data.y,
            data.y + data.h,
            data.y + data.h,
            data.y + data.h + 5.0
        );
        if rotate {
            let y = data.y + data.h + 12.0;
            let _ = write!(
                s,
                r#"<text class="tick-x" x="{x:.1}" y="{y:.1}" font-size="{FONT}" text-anchor="end" transform="rotate(-35 {x:.1} {y:.1})">{}</text>"#,
                escape(label)
            );
        } else {
            let _ = write!(
                s,
                r#"<text class="tick-x" x="{x:.1}" y="{:.1}" font-size="{FONT}" text-anchor="middle">{}</text>"#,
                data.y + data.h + 18.0,
                escape(label)
            );
        }
    }
    if x_axis.log {
        minor_ticks(&mut s, &x_axis, |v| {
            let x = px(v);
            format!(
                r##"<line x1="{x:.1}" y1="{:.1}" x2="{x:.1}" y2="{:.1}" stroke="#444"/>"##,
                data.y + data.h,
                data.y + data.h + 3.0
            )
        });
    }
    if let Some(note) = &x_axis.ticks.note {
        let _ = write!(
            s,
            r#"<text class="axis-note-x" x="{:.1}" y="{:.1}" font-size="{FONT}" text-anchor="end">{}</text>"#,
            data.x + data.w,
            data.y + data.h + x_tick_height + 16.0,
            escape(note)
        );
    }
    if !chart.x_label.is_empty() {
        let _ = write!(
            s,
            r#"<text class="axis-label-x" x="{:.1}" y="{:.1}" font-size="13" text-anchor="middle">{}</text>"#,
            data.x + data.w / 2.0,
            data.y + data.h + x_tick_height + 16.0,
            escape(chart.x_label)
        );
    }
    s.push_str("</g>");
    let _ = write!(
        s,
        r#"<g class="axis-y" data-scale="{}">"#,
        if y_axis.log { "log" } else { "linear" }
    );
    for (v, label) in y_axis.ticks.values.iter().zip(&y_axis.ticks.labels) {
        let y = py(*v);
        let _ = write!(
            s,
            r##"<line x1="{:.1}" y1="{y:.1}" x2="{:.1}" y2="{y:.1}" stroke="#ececec"/><line x1="{:.1}" y1="{y:.1}" x2="{:.1}" y2="{y:.1}" stroke="#444"/>"##,
            data.x,
            data.x + data.w,
            data.x - 5.0,
            data.x
        );
        let _ = write!(
            s,
            r#"<text class="tick-y" x="{:.1}" y="{:.1}" font-size="{FONT}" text-anchor="end">{}</text>"#,
            data.x - 8.0,
            y + 4.0,
            escape(label)
        );
    }
    if y_axis.log {
        minor_ticks(&mut s, &y_axis, |v| {
            let y = py(v);
            format!(
                r##"<line x1="{:.1}" y1="{y:.1}" x2="{:.1}" y2="{y:.1}" stroke="#444"/>"##,
                data.x - 3.0,
                data.x
            )
        });
    }
    if let Some(note) = &y_axis.ticks.note {
        let _ = write!(
            s,
            r#"<text class="axis-note-y" x="{:.1}" y="{:.1}" font-size="{FONT}" text-anchor="start">{}</text>"#,
            data.x,
            data.y - 6.0,
            escape(note)
        );
    }
    if !chart.y_label.is_empty() {
        let (x, y) = (16.0, data.y + data.h / 2.0);
        let _ = write!(
            s,
            r#"<text class="axis-label-y" x="{x:.1}" y="{y:.1}" font-size="13" text-anchor="middle" transform="rotate(-90 {x:.1} {y:.1})">{}</text>"#,
            escape(chart.y_label)
        );
    }
    s.push_str("</g>");
    // Bars, grouped per category.
    if !chart.bars.is_empty() {
        let zero = py(if y_axis.log { y_axis.lo } else { 0.0 });
        let k = chart.bars.len() as f64;
        let group = 0.8 / k;
        for (b, bars) in chart.bars.iter().enumerate() {
            for (i, &v) in bars.values.iter().enumerate() {
                let x0 = px(i as f64 + 1.0 - 0.4 + group * b as f64);
                let x1 = px(i as f64 + 1.0 - 0.4 + group * (b as f64 + 1.0));
                let v = if v.is_finite() { v } else { 0.0 };
                let y = py(v);
                if !y.is_finite() {
                    continue;
                }
                let _ = write!(
                    s,
                    r#"<rect class="bar" x="{x0:.1}" y="{:.1}" width="{:.1}" height="{:.1}" fill="{}"/>"#,
                    y.min(zero),
                    x1 - x0,
                    (zero - y).abs(),
                    rgb(bars.color)
                );
                if let Some(&(lo, hi)) = bars.intervals.get(i) {
                    let (a, b) = (py(lo), py(hi));
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
    // Series, in order: a later one is drawn above an earlier one.
    let _ = write!(s, r#"<g clip-path="url(#{clip})">"#);
    for series in chart.series {
        let color = rgb(series.color);
        let points: Vec<Option<(f64, f64)>> = series
            .time
            .iter()
            .zip(series.values)
            .map(|(&t, &v)| {
                let p = (px(t), py(v));
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
            continue;
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
            let piece = thin(&piece, data.w);
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
    s.push_str("</g>");
    let _ = write!(
        s,
        r##"<rect class="data-area" x="{:.1}" y="{:.1}" width="{:.1}" height="{:.1}" fill="none" stroke="#444"/>"##,
        data.x, data.y, data.w, data.h
    );
    if chart.direct_labels {
        direct_labels(&mut s, chart, &data, &px, &py);
    }
    if !entries.is_empty() {
        legend_svg(
            &mut s,
            &entries,
            &legend,
            entry_width,
            row,
            legend_right.then_some(((legend.h - 10.0) / row).round() as usize),
        );
    }
    s.push_str("</svg>\n");
    s
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

/// Each labelled line's label right of the data area at the height its line ends, pushed
/// apart so that none overlaps another.
fn direct_labels(
    s: &mut String,
    chart: &Chart,
    data: &Rect,
    px: &dyn Fn(f64) -> f64,
    py: &dyn Fn(f64) -> f64,
) {
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
                .map(|(&t, &v)| (px(t), py(v)))
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

/// The legend: a bordered box of entries in columns (filled column by column when
/// `rows_per_column` is given, else row by row).
fn legend_svg(
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

/// What a test (or a reader of the SVG) finds in a plot drawn by [`render`].
#[derive(Debug, Clone, Default)]
pub struct Anatomy {
    pub data_area: Option<Rect>,
    pub legend: Option<Rect>,
    pub x_ticks: Vec<String>,
    pub y_ticks: Vec<String>,
    pub x_scale: String,
    pub y_scale: String,
    pub y_note: Option<String>,
    pub x_note: Option<String>,
}

fn attribute(tag: &str, name: &str) -> Option<String> {
    let key = format!(" {name}=\"");
    let start = tag.find(&key)? + key.len();
    let end = tag[start..].find('"')? + start;
    Some(tag[start..end].to_string())
}

fn rect_of(tag: &str) -> Option<Rect> {
    let n = |k| attribute(tag, k).and_then(|v| v.parse::<f64>().ok());
    Some(Rect {
        x: n("x")?,
        y: n("y")?,
        w: n("width")?,
        h: n("height")?,
    })
}

fn unescape(text: &str) -> String {
    text.replace("&lt;", "<")
        .replace("&gt;", ">")
        .replace("&quot;", "\"")
        .replace("&amp;", "&")
}

/// Texts of the elements `<text class="{class}" …>…</text>` of `svg`.
fn texts(svg: &str, class: &str) -> Vec<String> {
    let key = format!("<text class=\"{class}\"");
    let mut out = Vec::new();
    let mut rest = svg;
    while let Some(at) = rest.find(&key) {
        rest = &rest[at..];
        let open = rest.find('>').map_or(rest.len(), |i| i + 1);
        let close = rest[open..]
            .find("</text>")
            .map_or(rest.len(), |i| i + open);
        out.push(unescape(&rest[open..close]));
        rest = &rest[close..];
    }
    out
}

/// Take `svg` apart: its data area, legend box, tick labels and axis scales.
pub fn anatomy(svg: &str) -> Anatomy {
    let tag = |class: &str| {
        let key = format!("class=\"{class}\"");
        svg.find(&key).map(|at| {
            let start = svg[..at].rfind('<').unwrap_or(0);
            let end = svg[at..].find('>').map_or(svg.len(), |i| i + at);
            svg[start..end].to_string()
        })
    };
    Anatomy {
        data_area: tag("data-area").and_then(|t| rect_of(&t)),
        legend: tag("legend-box").and_then(|t| rect_of(&t)),
        x_ticks: texts(svg, "tick-x"),
        y_ticks: texts(svg, "tick-y"),
        x_scale: tag("axis-x")
            .and_then(|t| attribute(&t, "data-scale"))
            .unwrap_or_default(),
        y_scale: tag("axis-y")
            .and_then(|t| attribute(&t, "data-scale"))
            .unwrap_or_default(),
        y_note: texts(svg, "axis-note-y").into_iter().next(),
        x_note: texts(svg, "axis-note-x").into_iter().next(),
    }
}

impl Anatomy {
    /// What makes the plot hard to read, if anything: repeated or "-0" tick labels, a
    /// legend over the data area.
    pub fn faults(&self) -> Vec<String> {
        let mut faults = Vec::new();
        for (axis, ticks) in [("x", &self.x_ticks), ("y", &self.y_ticks)] {
            let mut sorted = ticks.clone();
            sorted.sort();
            sorted.dedup();
            if sorted.len() != ticks.len() {
                faults.push(format!("{axis} tick labels repeat: {ticks:?}"));
            }
            if ticks.iter().any(|l| {
                l.strip_prefix('-')
                    .is_some_and(|r| r.chars().all(|c| c == '0' || c == '.'))
            }) {
                faults.push(format!("{axis} tick label reads minus zero: {ticks:?}"));
            }
            if ticks.len() < 2 {
                faults.push(format!("{axis} axis has fewer than two ticks: {ticks:?}"));
            }
        }
        match (&self.data_area, &self.legend) {
            (None, _) => faults.push("no data area".into()),
            (Some(d), Some(l)) if d.intersects(l) => {
                faults.push(format!("legend {l:?} over the data area {d:?}"))
            }
            _ => {}
        }
        faults
    }
}
