//! The SVG every plot of calib is drawn as: a data area with ticks from [`super::ticks`]
//! (linear or log, chosen by the caller or by the data), shaded ranges, lines, dots and
//! bars, and the legend beside the data area (to its right, or below it when it would be
//! too wide) so that it never covers a curve. Written by hand rather than through a
//! plotting crate so that every tick, label and box is placed by rules the tests can check:
//! the data area is the `rect` of class `data-area`, the legend box the `rect` of class
//! `legend-box`, tick labels `text` of class `tick-x` / `tick-y`, the scale of an axis the
//! `data-scale` of its `g` of class `axis-x` / `axis-y`.

mod anatomy;
mod axis;
mod layout;
mod legend;
mod marks;

pub use anatomy::{anatomy, Anatomy};
use axis::Axis;
use layout::Layout;
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

/// The data area and the axes that map values onto it.
struct Plane {
    data: Rect,
    x: Axis,
    y: Axis,
}

impl Plane {
    /// The pixel column of abscissa `v` (not finite off a log axis' domain).
    fn px(&self, v: f64) -> f64 {
        self.data.x + self.x.fraction(v) * self.data.w
    }

    /// The pixel row of ordinate `v` (not finite off a log axis' domain).
    fn py(&self, v: f64) -> f64 {
        self.data.y + self.data.h - self.y.fraction(v) * self.data.h
    }
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

/// The SVG text of `chart`.
pub fn render(chart: &Chart) -> String {
    let (width, height) = if chart.size.0 == 0 {
        (1000.0, 500.0)
    } else {
        (chart.size.0 as f64, chart.size.1 as f64)
    };
    let (x, y) = (axis::x_axis(chart), axis::y_axis(chart));
    let entries = legend::entries(chart);
    let layout = layout::place(chart, &x, &y, &entries, width, height);
    let plane = Plane {
        data: layout.data,
        x,
        y,
    };
    let mut s = String::new();
    let clip = canvas(&mut s, chart, &layout);
    marks::shades(&mut s, chart.shades, &plane);
    axis::draw_x(
        &mut s,
        &plane,
        chart.x_label,
        layout.rotate,
        layout.x_tick_height,
    );
    axis::draw_y(&mut s, &plane, chart.y_label);
    marks::bars(&mut s, chart.bars, &plane);
    marks::series(&mut s, chart.series, &plane, &clip);
    let data = &plane.data;
    let _ = write!(
        s,
        r##"<rect class="data-area" x="{:.1}" y="{:.1}" width="{:.1}" height="{:.1}" fill="none" stroke="#444"/>"##,
        data.x, data.y, data.w, data.h
    );
    if chart.direct_labels {
        legend::direct_labels(&mut s, chart, &plane);
    }
    if !entries.is_empty() {
        let legend = &layout.legend;
        legend::draw(
            &mut s,
            &entries,
            legend,
            layout.entry_width,
            layout::ROW,
            layout
                .legend_right
                .then_some(((legend.h - 10.0) / layout::ROW).round() as usize),
        );
    }
    s.push_str("</svg>\n");
    s
}

/// The opening of the SVG: the canvas, its white background, the title and the clip path
/// of the data area; the clip path's name.
fn canvas(s: &mut String, chart: &Chart, layout: &Layout) -> String {
    let (width, height, data) = (layout.width, layout.height, &layout.data);
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
    clip
}
