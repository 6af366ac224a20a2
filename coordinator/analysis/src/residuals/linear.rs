//! The small dense linear algebra diagnosis needs: projections onto spans of sensitivity
//! columns (modified Gram–Schmidt), and linear least squares with its covariance from the
//! singular value decomposition of the Jacobian (nalgebra), never from the normal matrix
//! `JᵀJ`, whose condition number is the square of `J`'s. Columns are long (every sample of
//! every output) but few.

pub fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// An orthonormal basis built one column at a time.
#[derive(Debug, Default, Clone)]
pub struct Basis {
    columns: Vec<Vec<f64>>,
}

impl Basis {
    /// `v` with its components along the basis removed (twice, for numerical safety).
    pub fn residual_of(&self, v: &[f64]) -> Vec<f64> {
        let mut out = v.to_vec();
        for _ in 0..2 {
            for q in &self.columns {
                let c = dot(q, &out);
                for (o, qi) in out.iter_mut().zip(q) {
                    *o -= c * qi;
                }
            }
        }
        out
    }

    /// Add `v` to the span unless it is (nearly) inside it already; true when added.
    pub fn push(&mut self, v: &[f64]) -> bool {
        let norm0 = dot(v, v).sqrt();
        let w = self.residual_of(v);
        let norm = dot(&w, &w).sqrt();
        if norm0 == 0.0 || norm <= 1e-10 * norm0 {
            return false;
        }
        self.columns.push(w.into_iter().map(|x| x / norm).collect());
        true
    }
}

/// Singular values of the column-scaled Jacobian below this fraction of the largest one
/// count as zero. The columns are finite-difference sensitivities, whose relative error is
/// near the square root of machine epsilon (1.5e-8); a direction weaker than that is
/// indistinguishable from the error of the differences themselves.
pub const RANK_TOLERANCE: f64 = 1e-8;

/// Most sweeps of the SVD; a handful suffice for the few columns here.
const SVD_ITERATIONS: usize = 1000;

/// Linear least squares `min ‖J x − r‖` through the singular value decomposition of `J`.
///
/// `J`'s columns are first scaled to unit length, so that the rank does not depend on the
/// parameters' units; a column of zeros (a parameter with no effect) is left as it is and
/// makes the problem rank deficient.
#[derive(Debug, Clone)]
pub struct LeastSquares {
    /// Length of each column of `J` (1 for a zero column).
    scale: Vec<f64>,
    /// `None` when `J` has no entries, or non-finite ones: nothing is resolved then.
    svd: Option<nalgebra::SVD<f64, nalgebra::Dyn, nalgebra::Dyn>>,
    /// Singular values above the tolerance, in the SVD's order.
    kept: Vec<bool>,
}

impl LeastSquares {
    /// Decomposes the `J` whose columns are given (all of the same length).
    pub fn new(columns: &[Vec<f64>]) -> LeastSquares {
        let rows = columns.first().map_or(0, Vec::len);
        let scale: Vec<f64> = columns
            .iter()
            .map(|column| {
                let norm = dot(column, column).sqrt();
                if norm > 0.0 && norm.is_finite() {
                    norm
                } else {
                    1.0
                }
            })
            .collect();
        let scaled =
            nalgebra::DMatrix::from_fn(rows, columns.len(), |i, j| columns[j][i] / scale[j]);
        let svd = (!scaled.is_empty() && scaled.iter().all(|x| x.is_finite()))
            .then(|| scaled.try_svd(true, true, f64::EPSILON, SVD_ITERATIONS))
            .flatten();
        let kept = match &svd {
            Some(svd) => {
                let largest = svd.singular_values.iter().copied().fold(0.0, f64::max);
                svd.singular_values
                    .iter()
                    .map(|&sigma| largest > 0.0 && sigma > RANK_TOLERANCE * largest)
                    .collect()
            }
            None => Vec::new(),
        };
        LeastSquares { scale, svd, kept }
    }

    /// The number of independent directions `J` resolves.
    pub fn rank(&self) -> usize {
        self.kept.iter().filter(|&&kept| kept).count()
    }

    /// Whether every parameter is determined (the rank equals the number of columns).
    pub fn is_full_rank(&self) -> bool {
        self.rank() == self.scale.len()
    }

    /// The least-squares solution of `J x = r` of least (scaled) length: the
    /// Gauss–Newton step when `r` is the residual.
    pub fn solve(&self, rhs: &[f64]) -> Vec<f64> {
        let mut x = vec![0.0; self.scale.len()];
        let Some(svd) = &self.svd else {
            return x;
        };
        let (Some(u), Some(v_t)) = (&svd.u, &svd.v_t) else {
            return x;
        };
        let rhs = nalgebra::DVector::from_column_slice(rhs);
        for (k, sigma) in svd.singular_values.iter().enumerate() {
            if !self.kept[k] {
                continue;
            }
            let coefficient = u.column(k).dot(&rhs) / sigma;
            for (j, x_j) in x.iter_mut().enumerate() {
                *x_j += coefficient * v_t[(k, j)];
            }
        }
        x.iter().zip(&self.scale).map(|(x, s)| x / s).collect()
    }

    /// `(JᵀJ)⁻¹`, or `None` when `J` is rank deficient and the parameters cannot all be
    /// told apart.
    pub fn covariance(&self) -> Option<Vec<Vec<f64>>> {
        let n = self.scale.len();
        if n == 0 {
            return Some(Vec::new());
        }
        if !self.is_full_rank() {
            return None;
        }
        let svd = self.svd.as_ref()?;
        let v_t = svd.v_t.as_ref()?;
        let sigma = &svd.singular_values;
        Some(
            (0..n)
                .map(|i| {
                    (0..n)
                        .map(|j| {
                            let scaled: f64 = (0..sigma.len())
                                .map(|k| v_t[(k, i)] * v_t[(k, j)] / (sigma[k] * sigma[k]))
                                .sum();
                            scaled / (self.scale[i] * self.scale[j])
                        })
                        .collect()
                })
                .collect(),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn projection_removes_the_span() {
        let mut basis = Basis::default();
        assert!(basis.push(&[1.0, 1.0, 0.0]));
        assert!(!basis.push(&[2.0, 2.0, 0.0]));
        let r = basis.residual_of(&[1.0, 0.0, 3.0]);
        assert!(
            (r[0] - 0.5).abs() < 1e-12 && (r[1] + 0.5).abs() < 1e-12 && (r[2] - 3.0).abs() < 1e-12
        );
    }

    /// Columns of the straight-line model `y = a + b t` on `t = 0, 1, …, m − 1`.
    fn line(m: usize) -> Vec<Vec<f64>> {
        vec![vec![1.0; m], (0..m).map(|t| t as f64).collect()]
    }

    #[test]
    fn straight_line_fit_has_the_textbook_covariance() {
        // For y = a + b t on t = 0..m−1, (JᵀJ)⁻¹ = [[Σt², −Σt], [−Σt, m]] / (m Σt² − (Σt)²).
        let m = 11;
        let columns = line(m);
        let fit = LeastSquares::new(&columns);
        assert!(fit.is_full_rank());
        let (s1, s2) = (55.0, 385.0);
        let det = m as f64 * s2 - s1 * s1;
        let expected = [[s2 / det, -s1 / det], [-s1 / det, m as f64 / det]];
        let covariance = fit.covariance().expect("full rank");
        for i in 0..2 {
            for j in 0..2 {
                assert!(
                    (covariance[i][j] - expected[i][j]).abs() < 1e-12 * expected[i][i].abs(),
                    "{i},{j}: {} vs {}",
                    covariance[i][j],
                    expected[i][j]
                );
            }
        }
        // Exact data are fitted exactly.
        let y: Vec<f64> = (0..m).map(|t| 2.0 - 0.5 * t as f64).collect();
        let x = fit.solve(&y);
        assert!(
            (x[0] - 2.0).abs() < 1e-12 && (x[1] + 0.5).abs() < 1e-12,
            "{x:?}"
        );
    }

    #[test]
    fn columns_of_very_different_scales_keep_their_precision() {
        // The same line with t in units of 1e-9: JᵀJ has a condition number near 1e38,
        // beyond what an inverse of it can resolve, while J's own is near 1e19 before
        // scaling and small after.
        let m = 11;
        let mut columns = line(m);
        for t in &mut columns[1] {
            *t *= 1e-9;
        }
        let fit = LeastSquares::new(&columns);
        assert!(fit.is_full_rank());
        let y: Vec<f64> = (0..m).map(|t| 2.0 - 0.5 * t as f64).collect();
        let x = fit.solve(&y);
        assert!((x[0] - 2.0).abs() < 1e-10, "{x:?}");
        assert!((x[1] / -0.5e9 - 1.0).abs() < 1e-10, "{x:?}");
        let covariance = fit.covariance().expect("full rank");
        let expected_bb = 11.0 / (11.0 * 385.0 - 55.0 * 55.0) * 1e18;
        assert!((covariance[1][1] / expected_bb - 1.0).abs() < 1e-10);
    }

    #[test]
    fn dependent_columns_are_rank_deficient() {
        let m = 8;
        let mut columns = line(m);
        // A third column equal to 3·(first) − 2·(second): the rank stays 2.
        columns.push((0..m).map(|t| 3.0 - 2.0 * t as f64).collect());
        let fit = LeastSquares::new(&columns);
        assert_eq!(fit.rank(), 2);
        assert!(fit.covariance().is_none());
        // The residual is still removed, by the step of least length.
        let y: Vec<f64> = (0..m).map(|t| 1.0 + t as f64).collect();
        let x = fit.solve(&y);
        for (t, measured) in y.iter().enumerate() {
            let fitted = x[0] + x[1] * t as f64 + x[2] * (3.0 - 2.0 * t as f64);
            assert!((fitted - measured).abs() < 1e-10, "{t}: {fitted}");
        }
    }

    #[test]
    fn nearly_dependent_columns_below_the_tolerance_are_rank_deficient() {
        let m = 8;
        let mut columns = line(m);
        let mut near: Vec<f64> = columns[1].clone();
        near[3] += 1e-10;
        columns.push(near.clone());
        assert_eq!(LeastSquares::new(&columns).rank(), 2);
        // Well above the tolerance the third direction is resolved.
        near[3] += 1e-4;
        columns[2] = near;
        assert_eq!(LeastSquares::new(&columns).rank(), 3);
    }

    #[test]
    fn non_finite_or_empty_jacobians_resolve_nothing() {
        let mut columns = line(4);
        columns[1][2] = f64::NAN;
        let fit = LeastSquares::new(&columns);
        assert_eq!(fit.rank(), 0);
        assert!(fit.covariance().is_none());
        assert_eq!(fit.solve(&[1.0; 4]), vec![0.0, 0.0]);
        assert_eq!(LeastSquares::new(&[]).covariance(), Some(Vec::new()));
        assert_eq!(LeastSquares::new(&[vec![], vec![]]).rank(), 0);
    }

    #[test]
    fn a_parameter_without_effect_is_rank_deficient() {
        let mut columns = line(5);
        columns.push(vec![0.0; 5]);
        let fit = LeastSquares::new(&columns);
        assert_eq!(fit.rank(), 2);
        assert!(!fit.is_full_rank());
        assert!(fit.covariance().is_none());
        assert_eq!(fit.solve(&[1.0; 5])[2], 0.0);
    }
}
