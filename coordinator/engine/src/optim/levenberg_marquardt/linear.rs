//! The small dense algebra of a Levenberg–Marquardt step: normal equations from Jacobian
//! columns, a damped solve over the parameters free to move, and Broyden's update.

/// A Jacobian by columns: `columns[j][i] = ∂r_i/∂x_j`.
pub type Columns = Vec<Vec<f64>>;

/// `JᵀJ` (row-major, `n × n`) and `Jᵀr`.
pub fn normal_equations(columns: &Columns, r: &[f64]) -> (Vec<Vec<f64>>, Vec<f64>) {
    let n = columns.len();
    let mut a = vec![vec![0.0; n]; n];
    for j in 0..n {
        for k in j..n {
            let v = dot(&columns[j], &columns[k]);
            a[j][k] = v;
            a[k][j] = v;
        }
    }
    let g = columns.iter().map(|c| dot(c, r)).collect();
    (a, g)
}

pub fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// Whether parameter `j` may move: not held at a bound by a gradient that pushes it out.
/// At `x_j = 0` a positive gradient (descent towards negative `x_j`) holds it; at 1 a
/// negative one does.
pub fn is_free(x: f64, gradient: f64) -> bool {
    !((x <= 0.0 && gradient > 0.0) || (x >= 1.0 && gradient < 0.0))
}

/// The damped Gauss–Newton step `δ` solving `(JᵀJ + λ D) δ = −Jᵀr` over the free
/// parameters (the others do not move), with Marquardt's scaling `D = diag(JᵀJ)` floored at
/// a small share of its largest entry so that a parameter without influence stays put.
/// `None` when the system is singular (no free parameter has influence).
pub fn damped_step(a: &[Vec<f64>], g: &[f64], lambda: f64, free: &[bool]) -> Option<Vec<f64>> {
    let n = g.len();
    let largest = (0..n).map(|j| a[j][j]).fold(0.0, f64::max);
    if largest <= 0.0 || !largest.is_finite() {
        return None;
    }
    let floor = DIAGONAL_FLOOR * largest;
    let index: Vec<usize> = (0..n).filter(|&j| free[j]).collect();
    let mut m: Vec<Vec<f64>> = index
        .iter()
        .map(|&j| {
            let mut row: Vec<f64> = index.iter().map(|&k| a[j][k]).collect();
            row.push(-g[j]);
            row
        })
        .collect();
    for (p, &j) in index.iter().enumerate() {
        m[p][p] += lambda * a[j][j].max(floor);
    }
    let solution = solve(m)?;
    let mut step = vec![0.0; n];
    for (p, &j) in index.iter().enumerate() {
        step[j] = solution[p];
    }
    Some(step)
}

/// Share of the largest diagonal entry of `JᵀJ` below which the damping's scale is floored.
const DIAGONAL_FLOOR: f64 = 1e-12;

/// Solve an augmented system `[M | b]` by Gaussian elimination with partial pivoting;
/// `None` when singular.
fn solve(mut m: Vec<Vec<f64>>) -> Option<Vec<f64>> {
    let n = m.len();
    for col in 0..n {
        let pivot = (col..n).max_by(|&a, &b| m[a][col].abs().total_cmp(&m[b][col].abs()))?;
        if m[pivot][col] == 0.0 || !m[pivot][col].is_finite() {
            return None;
        }
        m.swap(col, pivot);
        for row in col + 1..n {
            let factor = m[row][col] / m[col][col];
            if factor != 0.0 {
                let (upper, lower) = m.split_at_mut(row);
                for (a, b) in lower[0][col..].iter_mut().zip(&upper[col][col..]) {
                    *a -= factor * b;
                }
            }
        }
    }
    let mut x = vec![0.0; n];
    for row in (0..n).rev() {
        let tail: f64 = (row + 1..n).map(|k| m[row][k] * x[k]).sum();
        x[row] = (m[row][n] - tail) / m[row][row];
    }
    x.iter().all(|v| v.is_finite()).then_some(x)
}

/// Broyden's rank-one update of a Jacobian after the step `dx` changed the residuals by
/// `dr`: the least change to `J` with `J dx = dr`.
pub fn broyden(columns: &mut Columns, dx: &[f64], dr: &[f64]) {
    let norm = dot(dx, dx);
    if norm <= 0.0 {
        return;
    }
    // J dx − dr, per residual.
    let mut miss: Vec<f64> = dr.iter().map(|v| -v).collect();
    for (column, &d) in columns.iter().zip(dx) {
        for (m, c) in miss.iter_mut().zip(column) {
            *m += c * d;
        }
    }
    for (column, &d) in columns.iter_mut().zip(dx) {
        let share = d / norm;
        for (c, m) in column.iter_mut().zip(&miss) {
            *c -= m * share;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_undamped_step_solves_the_normal_equations() {
        // r = J x − b with J = [[1, 0], [0, 2], [1, 1]] at x = 0: the step is the least
        // squares solution of J δ = b.
        let columns = vec![vec![1.0, 0.0, 1.0], vec![0.0, 2.0, 1.0]];
        let b = [1.0, 2.0, 3.0];
        let r: Vec<f64> = b.iter().map(|v| -v).collect();
        let (a, g) = normal_equations(&columns, &r);
        let step = damped_step(&a, &g, 0.0, &[true, true]).unwrap();
        // JᵀJ = [[2, 1], [1, 5]], Jᵀb = [4, 7]: δ = [13/9, 10/9].
        assert!((step[0] - 13.0 / 9.0).abs() < 1e-14, "{step:?}");
        assert!((step[1] - 10.0 / 9.0).abs() < 1e-14, "{step:?}");
        // A held parameter does not move; the other solves its own equation.
        let held = damped_step(&a, &g, 0.0, &[false, true]).unwrap();
        assert_eq!(held[0], 0.0);
        assert!((held[1] - 7.0 / 5.0).abs() < 1e-14);
        // Damping shortens the step.
        let damped = damped_step(&a, &g, 10.0, &[true, true]).unwrap();
        assert!(damped[0].abs() < step[0].abs() && damped[1].abs() < step[1].abs());
    }

    #[test]
    fn a_jacobian_without_influence_is_singular() {
        let columns = vec![vec![0.0, 0.0], vec![0.0, 0.0]];
        let (a, g) = normal_equations(&columns, &[1.0, 1.0]);
        assert!(damped_step(&a, &g, 1.0, &[true, true]).is_none());
    }

    #[test]
    fn broyden_meets_the_secant_condition() {
        let mut columns = vec![vec![1.0, 0.0], vec![0.0, 1.0]];
        let (dx, dr) = ([0.5, 0.25], [2.0, -1.0]);
        broyden(&mut columns, &dx, &dr);
        for i in 0..2 {
            let jdx = columns[0][i] * dx[0] + columns[1][i] * dx[1];
            assert!((jdx - dr[i]).abs() < 1e-14, "{jdx} vs {}", dr[i]);
        }
    }

    #[test]
    fn bounds_hold_parameters_pushed_outwards() {
        assert!(!is_free(0.0, 1.0));
        assert!(is_free(0.0, -1.0));
        assert!(!is_free(1.0, -1.0));
        assert!(is_free(1.0, 1.0));
        assert!(is_free(0.5, 1.0));
    }
}
