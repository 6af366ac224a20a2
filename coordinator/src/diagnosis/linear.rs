//! The small dense linear algebra diagnosis needs: projections onto spans of sensitivity
//! columns (modified Gram–Schmidt) and the inverse of a normal matrix (Gauss–Jordan with
//! partial pivoting). Columns are long (every sample of every output) but few.

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

/// Inverse of a symmetric positive (semi)definite matrix, or `None` when singular.
pub fn invert(matrix: &[Vec<f64>]) -> Option<Vec<Vec<f64>>> {
    let n = matrix.len();
    let mut a: Vec<Vec<f64>> = matrix
        .iter()
        .enumerate()
        .map(|(i, row)| {
            let mut r = row.clone();
            r.extend((0..n).map(|j| if i == j { 1.0 } else { 0.0 }));
            r
        })
        .collect();
    let scale = (0..n).map(|i| matrix[i][i].abs()).fold(0.0, f64::max);
    for col in 0..n {
        let pivot = (col..n).max_by(|&x, &y| a[x][col].abs().total_cmp(&a[y][col].abs()))?;
        if a[pivot][col].abs() <= 1e-14 * scale.max(f64::MIN_POSITIVE) {
            return None;
        }
        a.swap(col, pivot);
        let p = a[col][col];
        for v in a[col].iter_mut() {
            *v /= p;
        }
        let pivot_row = a[col].clone();
        for (row, values) in a.iter_mut().enumerate() {
            let f = values[col];
            if row != col && f != 0.0 {
                for (v, p) in values.iter_mut().zip(&pivot_row) {
                    *v -= f * p;
                }
            }
        }
    }
    Some(a.into_iter().map(|r| r[n..].to_vec()).collect())
}

/// `JᵀJ` of a matrix given by its columns.
pub fn normal_matrix(columns: &[Vec<f64>]) -> Vec<Vec<f64>> {
    columns
        .iter()
        .map(|a| columns.iter().map(|b| dot(a, b)).collect())
        .collect()
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

    #[test]
    fn inverse_of_a_small_matrix() {
        let m = vec![vec![4.0, 1.0], vec![1.0, 3.0]];
        let inv = invert(&m).unwrap();
        let det = 11.0;
        assert!((inv[0][0] - 3.0 / det).abs() < 1e-12);
        assert!((inv[0][1] + 1.0 / det).abs() < 1e-12);
        assert!(invert(&[vec![1.0, 2.0], vec![2.0, 4.0]]).is_none());
    }
}
