//! Axis ticks that read: positions at nice numbers (1, 2, 5 times a power of ten, or the
//! decades of a log axis) and labels with the fewest digits that tell them apart, never
//! "-0". A range too narrow for its magnitude (9.042860 to 9.042866) is labelled by its
//! differences from an offset ("+9.04286"), a range of very small or very large numbers
//! (0.0010 to 0.0011) with a common scale ("×1e-3"), noted once beside the axis.

/// The ticks of one axis.
#[derive(Debug, Clone, PartialEq)]
pub struct Ticks {
    /// Positions, ascending, all within the axis' range.
    pub values: Vec<f64>,
    /// One label per position, all distinct.
    pub labels: Vec<String>,
    /// What the labels are relative to ("×1e-3", "+9.04286", "+9.04286, ×1e-6"), if anything.
    pub note: Option<String>,
}

/// The range an axis shows for data spanning `[lo, hi]`: the range itself, widened when it
/// is empty (a constant series) so that its one value sits in the middle.
pub fn widen(lo: f64, hi: f64) -> (f64, f64) {
    if !(lo.is_finite() && hi.is_finite()) {
        return (0.0, 1.0);
    }
    let (lo, hi) = if lo <= hi { (lo, hi) } else { (hi, lo) };
    let scale = lo.abs().max(hi.abs());
    if hi - lo > scale * 1e-12 && hi > lo {
        return (lo, hi);
    }
    let half = if scale > 0.0 { scale * 0.05 } else { 0.5 };
    (lo - half, hi + half)
}

/// A nice step (1, 2 or 5 times a power of ten) near `raw`.
fn nice_step(raw: f64) -> f64 {
    let magnitude = 10f64.powf(raw.log10().floor());
    let norm = raw / magnitude;
    let nice = if norm < 1.5 {
        1.0
    } else if norm < 3.5 {
        2.0
    } else if norm < 7.5 {
        5.0
    } else {
        10.0
    };
    nice * magnitude
}

/// `v` with `decimals` digits after the point, "-0" written "0".
fn fixed(v: f64, decimals: usize) -> String {
    let s = format!("{v:.decimals$}");
    match s.strip_prefix('-') {
        Some(rest) if rest.chars().all(|c| c == '0' || c == '.') => rest.to_string(),
        _ => s,
    }
}

/// Labels of `values` (multiples of `step`) in fixed notation with the fewest decimals
/// that keep them distinct and each within a hundredth of a step of its value.
fn fewest_digits(values: &[f64], step: f64) -> Vec<String> {
    for decimals in 0..=17 {
        let labels: Vec<String> = values.iter().map(|&v| fixed(v, decimals)).collect();
        let faithful = labels
            .iter()
            .zip(values)
            .all(|(l, v)| l.parse::<f64>().is_ok_and(|p| (p - v).abs() <= step * 0.01));
        let mut sorted = labels.clone();
        sorted.sort();
        sorted.dedup();
        if faithful && sorted.len() == labels.len() {
            return labels;
        }
    }
    values.iter().map(|v| format!("{v:e}")).collect()
}

/// Exponent a power of ten is written with: a multiple of 3 (`1e-3`, `1e6`).
fn engineering(v: f64) -> i32 {
    (v.abs().log10().floor() / 3.0).floor() as i32 * 3
}

/// Ticks of a linear axis over `[lo, hi]`, about `target` of them.
pub fn linear(lo: f64, hi: f64, target: usize) -> Ticks {
    let (lo, hi) = widen(lo, hi);
    let step = nice_step((hi - lo) / target.max(1) as f64);
    let first = (lo / step - 1e-9).ceil() as i64;
    let last = (hi / step + 1e-9).floor() as i64;
    let mut values: Vec<f64> = (first..=last)
        .map(|k| {
            let v = k as f64 * step;
            if v.abs() < step * 1e-9 {
                0.0
            } else {
                v
            }
        })
        .collect();
    if values.is_empty() {
        values.push((lo + hi) / 2.0);
    }
    label_linear(values, step)
}

/// Labels for linear ticks `values`, `step` apart.
fn label_linear(values: Vec<f64>, step: f64) -> Ticks {
    let largest = values.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    // Significant digits a label would need: from the largest value's first digit to the
    // step's.
    let digits = if largest > 0.0 {
        largest.log10().floor() - step.log10().floor() + 1.0
    } else {
        1.0
    };
    let mut notes = Vec::new();
    let mut shown = values.clone();
    let mut shown_step = step;
    if digits > 6.0 {
        // Too many digits for the spread: label the differences from a round offset.
        let unit = 10f64.powf((step * 10.0).log10().ceil());
        let offset = (values[0] / unit + 1e-6).floor() * unit;
        let decimals = (-unit.log10().floor()).max(0.0) as usize;
        notes.push(format!("+{}", fixed(offset, decimals)));
        shown = values.iter().map(|v| v - offset).collect();
    }
    let largest = shown.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    if largest > 0.0 && !(1e-2..1e5).contains(&largest) {
        let e = engineering(largest);
        let factor = 10f64.powi(e);
        shown = shown.iter().map(|v| v / factor).collect();
        shown_step = step / factor;
        notes.push(format!("×1e{e}"));
    }
    let labels = fewest_digits(&shown, shown_step);
    Ticks {
        values,
        labels,
        note: if notes.is_empty() {
            None
        } else {
            Some(notes.join(", "))
        },
    }
}

/// `m × 10^k` as a log axis labels it: plainly from 0.001 to 10000, else `me k`.
fn log_label(m: f64, k: i32) -> String {
    let m = m.round() as i64;
    if (-3..=4).contains(&k) {
        let v = m as f64 * 10f64.powi(k);
        fixed(v, (-k).max(0) as usize)
    } else {
        format!("{m}e{k}")
    }
}

/// Ticks of a log axis over `[lo, hi]` (both positive): the decades (every second or
/// further one over many), with 2 and 5 between them when fewer than two decades show, and
/// linear ticks when the range is within one decade and holds fewer than three of those.
pub fn log(lo: f64, hi: f64) -> Ticks {
    if !(lo > 0.0 && hi > lo && lo.is_finite() && hi.is_finite()) {
        let (lo, hi) = widen(lo.max(f64::MIN_POSITIVE), hi.max(f64::MIN_POSITIVE));
        return linear(lo, hi, 5);
    }
    let inside = |v: f64| v >= lo * (1.0 - 1e-9) && v <= hi * (1.0 + 1e-9);
    let k0 = lo.log10().floor() as i32;
    let k1 = hi.log10().ceil() as i32;
    let decades: Vec<i32> = (k0..=k1).filter(|&k| inside(10f64.powi(k))).collect();
    let mut values = Vec::new();
    let mut labels = Vec::new();
    if decades.len() >= 2 {
        let every = decades.len().div_ceil(8).max(1);
        for &k in decades.iter().step_by(every) {
            values.push(10f64.powi(k));
            labels.push(log_label(1.0, k));
        }
    } else {
        for k in k0 - 1..=k1 {
            for m in [1.0, 2.0, 5.0] {
                let v = m * 10f64.powi(k);
                if inside(v) {
                    values.push(v);
                    labels.push(log_label(m, k));
                }
            }
        }
        if values.len() < 3 {
            return linear(lo, hi, 4);
        }
    }
    Ticks {
        values,
        labels,
        note: None,
    }
}

/// Whether positive data over `[lo, hi]` spans more than two decades: drawn on a log axis.
pub fn spans_decades(lo: f64, hi: f64) -> bool {
    lo > 0.0 && hi.is_finite() && hi / lo > 100.0
}

#[cfg(test)]
mod tests {
    use super::*;

    fn negative_zero(l: &str) -> bool {
        l.strip_prefix('-')
            .is_some_and(|rest| rest.chars().all(|c| c == '0' || c == '.'))
    }

    fn distinct(t: &Ticks) -> bool {
        let mut l = t.labels.clone();
        l.sort();
        l.dedup();
        l.len() == t.labels.len()
    }

    fn check(t: &Ticks, lo: f64, hi: f64) {
        assert!(t.values.len() >= 2, "{t:?}");
        assert_eq!(t.values.len(), t.labels.len());
        assert!(distinct(t), "labels repeat: {t:?}");
        assert!(!t.labels.iter().any(|l| negative_zero(l)), "{t:?}");
        let (lo, hi) = widen(lo, hi);
        let eps = (hi - lo) * 1e-9;
        assert!(
            t.values.iter().all(|v| *v >= lo - eps && *v <= hi + eps),
            "{t:?}"
        );
        assert!(t.values.windows(2).all(|w| w[0] < w[1]), "{t:?}");
    }

    #[test]
    fn a_narrow_range_of_small_numbers_is_labelled_with_a_scale() {
        let t = linear(0.0010, 0.0011, 5);
        check(&t, 0.0010, 0.0011);
        assert_eq!(t.note.as_deref(), Some("×1e-3"), "{t:?}");
        assert_eq!(t.labels, ["1.00", "1.02", "1.04", "1.06", "1.08", "1.10"]);
    }

    #[test]
    fn a_range_narrow_for_its_magnitude_gets_enough_digits() {
        let t = linear(9.042860, 9.042866, 5);
        check(&t, 9.042860, 9.042866);
        assert!(t.values.len() >= 4, "{t:?}");
        // Either every label carries the seventh digit or they are differences from an offset.
        match &t.note {
            None => assert!(t.labels.iter().all(|l| l.len() >= 8), "{t:?}"),
            Some(note) => assert!(note.starts_with("+9.04286"), "{t:?}"),
        }
        let t = linear(1000.0001, 1000.0002, 5);
        check(&t, 1000.0001, 1000.0002);
        assert!(
            t.note.as_deref().is_some_and(|n| n.starts_with("+1000")),
            "{t:?}"
        );
    }

    #[test]
    fn ordinary_ranges_read_as_written() {
        let t = linear(0.0, 40.0, 8);
        assert_eq!(
            t.labels,
            ["0", "5", "10", "15", "20", "25", "30", "35", "40"]
        );
        assert_eq!(t.note, None);
        let t = linear(-0.3, 0.3, 6);
        check(&t, -0.3, 0.3);
        assert_eq!(
            t.labels,
            ["-0.3", "-0.2", "-0.1", "0.0", "0.1", "0.2", "0.3"]
        );
        let t = linear(-2.5e-7, 1e-7, 5);
        check(&t, -2.5e-7, 1e-7);
        assert!(t.note.as_deref() == Some("×1e-9"), "{t:?}");
    }

    #[test]
    fn no_tick_reads_minus_zero() {
        for (lo, hi) in [(-1.0, 1.0), (-0.05, 0.05), (-1e-9, 3e-9), (-7.0, 0.0)] {
            let t = linear(lo, hi, 7);
            check(&t, lo, hi);
            assert!(
                t.labels
                    .iter()
                    .any(|l| l.trim_end_matches('0') == "0." || l == "0"),
                "{t:?}"
            );
        }
    }

    #[test]
    fn a_constant_series_gets_a_range_around_its_value() {
        let t = linear(9.04, 9.04, 5);
        check(&t, 9.04, 9.04);
        assert!(
            t.values[0] < 9.04 && *t.values.last().unwrap() > 9.04,
            "{t:?}"
        );
        let t = linear(0.0, 0.0, 5);
        check(&t, 0.0, 0.0);
    }

    #[test]
    fn log_axes_tick_decades_and_fill_in_short_ones() {
        let t = log(3e-4, 2e3);
        check(&t, 3e-4, 2e3);
        assert_eq!(t.labels, ["0.001", "0.01", "0.1", "1", "10", "100", "1000"]);
        let t = log(1e-12, 1e12);
        check(&t, 1e-12, 1e12);
        assert!(t.values.len() <= 9, "{t:?}");
        assert!(t.labels.contains(&"1e-12".to_string()), "{t:?}");
        let t = log(0.3, 8.0);
        check(&t, 0.3, 8.0);
        assert_eq!(t.labels, ["0.5", "1", "2", "5"]);
        // Within a decade: linear ticks on the log axis, still distinct.
        let t = log(9.042860, 9.042866);
        check(&t, 9.042860, 9.042866);
    }

    #[test]
    fn decades_are_recognised() {
        assert!(spans_decades(1e-3, 1.0));
        assert!(!spans_decades(1.0, 50.0));
        assert!(!spans_decades(-1.0, 1e6));
    }
}
