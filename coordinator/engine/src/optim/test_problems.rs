//! Test problems shared by the solvers' tests.

use argmin::core::{CostFunction, Error, SyncAlias};
use std::sync::Mutex;

/// `sum (x_i - c_i)^2`.
pub struct Sphere {
    pub centre: Vec<f64>,
}

impl CostFunction for Sphere {
    type Param = Vec<f64>;
    type Output = f64;
    fn cost(&self, x: &Vec<f64>) -> Result<f64, Error> {
        Ok(x.iter()
            .zip(&self.centre)
            .map(|(a, c)| (a - c) * (a - c))
            .sum())
    }
}

/// Rosenbrock's function with the unit box mapped onto `[-2, 2]^2`; the minimum
/// `(1, 1)` sits at `(0.75, 0.75)`.
pub struct Rosenbrock;

impl CostFunction for Rosenbrock {
    type Param = Vec<f64>;
    type Output = f64;
    fn cost(&self, u: &Vec<f64>) -> Result<f64, Error> {
        let (x, y) = (4.0 * u[0] - 2.0, 4.0 * u[1] - 2.0);
        Ok((1.0 - x).powi(2) + 100.0 * (y - x * x).powi(2))
    }
}

/// Rastrigin's function with the unit box mapped onto `[-5.12, 5.12]^n`: a regular grid of
/// local minima about 1 apart; the global minimum 0 sits at the centre `(0.5, …)`.
pub struct Rastrigin;

impl CostFunction for Rastrigin {
    type Param = Vec<f64>;
    type Output = f64;
    fn cost(&self, u: &Vec<f64>) -> Result<f64, Error> {
        Ok(u.iter()
            .map(|v| {
                let x = 10.24 * v - 5.12;
                x * x - 10.0 * (std::f64::consts::TAU * x).cos() + 10.0
            })
            .sum())
    }
}

/// Records every evaluated point and how it was requested.
pub struct Recorder<O> {
    inner: O,
    pub points: Mutex<Vec<Vec<f64>>>,
    pub batch_sizes: Mutex<Vec<usize>>,
    pub single_calls: Mutex<usize>,
}

impl<O> Recorder<O> {
    pub fn new(inner: O) -> Self {
        Recorder {
            inner,
            points: Mutex::new(Vec::new()),
            batch_sizes: Mutex::new(Vec::new()),
            single_calls: Mutex::new(0),
        }
    }
}

impl<O: CostFunction<Param = Vec<f64>, Output = f64>> CostFunction for Recorder<O> {
    type Param = Vec<f64>;
    type Output = f64;

    fn cost(&self, x: &Vec<f64>) -> Result<f64, Error> {
        *self.single_calls.lock().unwrap() += 1;
        self.points.lock().unwrap().push(x.clone());
        self.inner.cost(x)
    }

    fn bulk_cost<P>(&self, params: &[P]) -> Result<Vec<f64>, Error>
    where
        P: std::borrow::Borrow<Vec<f64>> + SyncAlias,
        Self::Output: argmin::core::SendAlias,
        Self: SyncAlias,
    {
        self.batch_sizes.lock().unwrap().push(params.len());
        let mut points = self.points.lock().unwrap();
        params
            .iter()
            .map(|p| {
                points.push(p.borrow().clone());
                self.inner.cost(p.borrow())
            })
            .collect()
    }
}

use super::levenberg_marquardt::Residuals;

/// Costs with their residuals, from a residual function.
fn with_costs(points: &[Vec<f64>], r: impl Fn(&[f64]) -> Vec<f64>) -> Vec<(f64, Vec<f64>)> {
    points
        .iter()
        .map(|p| {
            let r = r(p);
            (r.iter().map(|v| v * v).sum(), r)
        })
        .collect()
}

/// The sphere's residuals `x_i − c_i`.
impl Residuals for Sphere {
    fn residuals(&self, points: &[Vec<f64>]) -> Result<Vec<(f64, Vec<f64>)>, Error> {
        Ok(with_costs(points, |x| {
            x.iter().zip(&self.centre).map(|(a, c)| a - c).collect()
        }))
    }
}

/// Rosenbrock's residuals `(1 − x, 10 (y − x²))`.
impl Residuals for Rosenbrock {
    fn residuals(&self, points: &[Vec<f64>]) -> Result<Vec<(f64, Vec<f64>)>, Error> {
        Ok(with_costs(points, |u| {
            let (x, y) = (4.0 * u[0] - 2.0, 4.0 * u[1] - 2.0);
            vec![1.0 - x, 10.0 * (y - x * x)]
        }))
    }
}

impl<O: Residuals> Residuals for Recorder<O> {
    fn residuals(&self, points: &[Vec<f64>]) -> Result<Vec<(f64, Vec<f64>)>, Error> {
        self.batch_sizes.lock().unwrap().push(points.len());
        self.points.lock().unwrap().extend(points.iter().cloned());
        self.inner.residuals(points)
    }
}
