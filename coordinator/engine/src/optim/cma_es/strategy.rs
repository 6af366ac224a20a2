//! One CMA-ES descent: the mean, the step size, the covariance matrix and their paths, with
//! Hansen's default parameters (Hansen 2016, "The CMA Evolution Strategy: A Tutorial",
//! table 1, positive recombination weights only).

use nalgebra::{DMatrix, DVector, SymmetricEigen};
use rand::Rng;
use rand_chacha::ChaCha8Rng;

/// The strategy parameters of a population size in `n` dimensions.
#[derive(Clone, Debug)]
pub struct Parameters {
    pub lambda: usize,
    pub mu: usize,
    /// Recombination weights of the `mu` best, decreasing, summing to 1.
    pub weights: Vec<f64>,
    pub mueff: f64,
    pub cc: f64,
    pub cs: f64,
    pub c1: f64,
    pub cmu: f64,
    pub damps: f64,
    /// E‖N(0, I)‖.
    pub chi_n: f64,
}

/// The default population size `4 + ⌊3 ln n⌋`.
pub fn default_lambda(n: usize) -> usize {
    4 + (3.0 * (n as f64).ln()).floor() as usize
}

impl Parameters {
    pub fn new(n: usize, lambda: usize) -> Self {
        let nf = n as f64;
        let mu = lambda / 2;
        let raw: Vec<f64> = (1..=mu)
            .map(|i| ((lambda as f64 + 1.0) / 2.0).ln() - (i as f64).ln())
            .collect();
        let total: f64 = raw.iter().sum();
        let weights: Vec<f64> = raw.iter().map(|w| w / total).collect();
        let mueff = 1.0 / weights.iter().map(|w| w * w).sum::<f64>();
        let cc = (4.0 + mueff / nf) / (nf + 4.0 + 2.0 * mueff / nf);
        let cs = (mueff + 2.0) / (nf + mueff + 5.0);
        let c1 = 2.0 / ((nf + 1.3).powi(2) + mueff);
        let cmu = (1.0 - c1).min(2.0 * (mueff - 2.0 + 1.0 / mueff) / ((nf + 2.0).powi(2) + mueff));
        let damps = 1.0 + 2.0 * (((mueff - 1.0) / (nf + 1.0)).sqrt() - 1.0).max(0.0) + cs;
        let chi_n = nf.sqrt() * (1.0 - 1.0 / (4.0 * nf) + 1.0 / (21.0 * nf * nf));
        Self {
            lambda,
            mu,
            weights,
            mueff,
            cc,
            cs,
            c1,
            cmu,
            damps,
            chi_n,
        }
    }
}

/// The state of one descent.
#[derive(Clone, Debug)]
pub struct Descent {
    pub p: Parameters,
    pub mean: DVector<f64>,
    pub sigma: f64,
    pub c: DMatrix<f64>,
    /// Eigenvectors of `c` (columns) and the square roots of its eigenvalues.
    pub b: DMatrix<f64>,
    pub d: DVector<f64>,
    pub pc: DVector<f64>,
    pub ps: DVector<f64>,
    /// Generations of this descent so far.
    pub generation: u64,
}

/// One generation's samples: `y = B D z` (the step before `sigma`), `x = mean + sigma y`.
pub struct Samples {
    pub y: Vec<DVector<f64>>,
    pub x: Vec<Vec<f64>>,
}

impl Descent {
    /// A descent from `mean` whose first samples spread by `spread[i]` along coordinate `i`:
    /// `sigma = max spread`, `C = diag((spread / sigma)²)`.
    pub fn new(mean: &[f64], spread: &[f64], lambda: usize) -> Self {
        let n = mean.len();
        let sigma = spread.iter().copied().fold(0.0, f64::max);
        let scales = DVector::from_iterator(n, spread.iter().map(|s| s / sigma));
        let c = DMatrix::from_diagonal(&scales.map(|s| s * s));
        Self {
            p: Parameters::new(n, lambda),
            mean: DVector::from_column_slice(mean),
            sigma,
            c,
            b: DMatrix::identity(n, n),
            d: scales,
            pc: DVector::zeros(n),
            ps: DVector::zeros(n),
            generation: 0,
        }
    }

    /// Draw the generation's `lambda` points.
    pub fn sample(&self, rng: &mut ChaCha8Rng) -> Samples {
        let n = self.mean.len();
        let mut y = Vec::with_capacity(self.p.lambda);
        let mut x = Vec::with_capacity(self.p.lambda);
        for _ in 0..self.p.lambda {
            let z = DVector::from_iterator(n, (0..n).map(|_| normal(rng)));
            let step = &self.b * self.d.component_mul(&z);
            x.push((&self.mean + self.sigma * &step).iter().copied().collect());
            y.push(step);
        }
        Samples { y, x }
    }

    /// Update from the generation's steps `y`, ordered best first by `order` (indices into
    /// `y`): mean, evolution paths, step size (CSA), covariance (rank-one and rank-μ).
    pub fn update(&mut self, y: &[DVector<f64>], order: &[usize]) {
        let p = &self.p;
        let n = self.mean.len() as f64;
        let mut yw = DVector::zeros(self.mean.len());
        for (w, &i) in p.weights.iter().zip(order) {
            yw += *w * &y[i];
        }
        self.mean += self.sigma * &yw;
        // C^(-1/2) y_w = B D⁻¹ Bᵀ y_w.
        let inv_sqrt = &self.b * (self.b.transpose() * &yw).component_div(&self.d);
        self.ps = (1.0 - p.cs) * &self.ps + (p.cs * (2.0 - p.cs) * p.mueff).sqrt() * inv_sqrt;
        self.generation += 1;
        let ps_norm = self.ps.norm();
        let decay = 1.0 - (1.0 - p.cs).powi(2 * self.generation.min(1 << 20) as i32);
        let hsig = ps_norm / decay.sqrt() / p.chi_n < 1.4 + 2.0 / (n + 1.0);
        let h = if hsig { 1.0 } else { 0.0 };
        self.pc = (1.0 - p.cc) * &self.pc + h * (p.cc * (2.0 - p.cc) * p.mueff).sqrt() * &yw;
        let mut rank_mu = DMatrix::zeros(self.c.nrows(), self.c.ncols());
        for (w, &i) in p.weights.iter().zip(order) {
            rank_mu += *w * &y[i] * y[i].transpose();
        }
        let delta = (1.0 - h) * p.cc * (2.0 - p.cc);
        self.c = (1.0 - p.c1 - p.cmu + p.c1 * delta) * &self.c
            + p.c1 * &self.pc * self.pc.transpose()
            + p.cmu * rank_mu;
        self.sigma *= ((p.cs / p.damps) * (ps_norm / p.chi_n - 1.0))
            .min(1.0)
            .exp();
        self.decompose();
    }

    /// Eigendecompose `C` (kept symmetric) into `B` and `D`.
    fn decompose(&mut self) {
        let symmetric = (&self.c + self.c.transpose()) * 0.5;
        self.c = symmetric.clone();
        let eigen = SymmetricEigen::new(symmetric);
        self.b = eigen.eigenvectors;
        self.d = eigen.eigenvalues.map(|v| v.max(1e-300).sqrt());
    }

    /// Largest over smallest eigenvalue of `C`.
    pub fn condition(&self) -> f64 {
        let max = self.d.max();
        let min = self.d.min();
        (max / min).powi(2)
    }

    /// Widen the step size when the best and a middle point of a generation tie (a flat
    /// fitness; Hansen 2016, appendix B.3).
    pub fn widen(&mut self) {
        self.sigma *= (0.2 + self.p.cs / self.p.damps).exp();
    }
}

/// A standard normal deviate (Box–Muller), from `rng` alone so that runs are reproducible.
fn normal(rng: &mut ChaCha8Rng) -> f64 {
    let u1: f64 = 1.0 - rng.random::<f64>();
    let u2: f64 = rng.random::<f64>();
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}
