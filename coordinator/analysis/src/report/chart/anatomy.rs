//! Reading a plot back: where [`render`](super::render) put its data area and legend, its
//! tick labels and scales, and what makes it hard to read.

use super::Rect;

/// What a test (or a reader of the SVG) finds in a plot drawn by [`render`](super::render).
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
