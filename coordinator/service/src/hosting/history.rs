//! A campaign's progress over time, as the coordinator keeps it: evaluations and each run's
//! best objective at moments spread over the campaign, at most [`MAX_POINTS`] of them, so a
//! page reopening the campaign (or reloaded while it runs) draws the whole history, not
//! only what it saw itself.

use calib_engine::store::ProgressPoint;

/// Most points a history keeps: thinned to half (every other point, the last kept) when
/// it would hold more.
pub const MAX_POINTS: usize = 200;

/// A campaign's progress points, the last always its newest state.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct History {
    points: Vec<ProgressPoint>,
    /// Fewest evaluations between two kept points (the last point is replaced until the
    /// campaign is this far past the one before it).
    spacing: u64,
}

impl History {
    /// A history that goes on from `points` (as the store kept them).
    pub fn from_points(points: Vec<ProgressPoint>) -> Self {
        let mut history = Self { points, spacing: 1 };
        history.respace();
        history
    }

    pub fn points(&self) -> &[ProgressPoint] {
        &self.points
    }

    /// The campaign now: `evaluations` so far and each run's best objective (`+∞` before
    /// a run's first point).
    pub fn record(&mut self, evaluations: u64, run_best: &[f64]) {
        let point = ProgressPoint {
            evaluations,
            run_best: run_best
                .iter()
                .map(|&v| v.is_finite().then_some(v))
                .collect(),
        };
        let n = self.points.len();
        let same = self
            .points
            .last()
            .is_some_and(|p| p.evaluations >= evaluations);
        if same || (n >= 2 && evaluations < self.points[n - 2].evaluations + self.spacing) {
            self.points[n - 1] = point;
        } else {
            self.points.push(point);
        }
        if self.points.len() > MAX_POINTS {
            let last = self.points.len() - 1;
            let mut k = 0;
            self.points.retain(|_| {
                let keep = k % 2 == 0 || k == last;
                k += 1;
                keep
            });
            self.respace();
        }
    }

    /// How many points it holds.
    pub fn len(&self) -> usize {
        self.points.len()
    }

    pub fn is_empty(&self) -> bool {
        self.points.is_empty()
    }

    /// Space points so that the evaluations so far fill half the history.
    fn respace(&mut self) {
        let span = match (self.points.first(), self.points.last()) {
            (Some(a), Some(b)) => b.evaluations.saturating_sub(a.evaluations),
            _ => 0,
        };
        self.spacing = self.spacing.max(span / (MAX_POINTS as u64 / 2)).max(1);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_long_campaign_keeps_a_bounded_history_spread_over_it_ending_at_its_last_state() {
        let mut h = History::default();
        for e in 1..=100_000u64 {
            h.record(e, &[1.0 / e as f64, f64::INFINITY]);
        }
        let points = h.points();
        assert!(points.len() <= MAX_POINTS, "{}", points.len());
        assert!(points.len() >= MAX_POINTS / 4, "{}", points.len());
        assert_eq!(points[0].evaluations, 1);
        let last = points.last().unwrap();
        assert_eq!(last.evaluations, 100_000);
        assert_eq!(last.run_best, vec![Some(1.0 / 100_000.0), None]);
        // Increasing, and no stretch of the campaign left without a point.
        assert!(points
            .windows(2)
            .all(|w| w[0].evaluations < w[1].evaluations));
        let widest = points
            .windows(2)
            .map(|w| w[1].evaluations - w[0].evaluations)
            .max()
            .unwrap();
        assert!(widest <= 100_000 / (MAX_POINTS as u64 / 8), "{widest}");
    }

    #[test]
    fn a_short_campaign_keeps_every_state() {
        let mut h = History::default();
        for e in 1..=50u64 {
            h.record(e, &[e as f64]);
        }
        assert_eq!(h.len(), 50);
        let again = History::from_points(h.points().to_vec());
        assert_eq!(again.points(), h.points());
    }
}
