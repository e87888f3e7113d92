//! Levenberg-Marquardt over a state on a manifold (poses): the problem gives residuals and a
//! retraction `state (+) delta`; the Jacobian is taken by central differences.

use super::linalg::{cholesky, cholesky_solve};

/// A least-squares problem.
pub trait Problem {
    /// What is optimised.
    type State: Clone;
    /// Number of parameters in a step.
    fn dim(&self) -> usize;
    /// The residuals at `s`, appended to `out` (cleared first by the caller).
    fn residuals(&self, s: &Self::State, out: &mut Vec<f64>);
    /// `s (+) delta`.
    fn retract(&self, s: &Self::State, delta: &[f64]) -> Self::State;
    /// Finite-difference step of parameter `k`.
    fn step(&self, k: usize) -> f64;
}

/// How a solve went.
#[derive(Debug, Clone, PartialEq)]
pub struct Report {
    /// Iterations run.
    pub iterations: usize,
    /// Sum of squared residuals before.
    pub initial_cost: f64,
    /// Sum of squared residuals after.
    pub final_cost: f64,
    /// Number of residuals.
    pub residuals: usize,
    /// Whether the step or the cost change fell below the tolerance.
    pub converged: bool,
}

/// The solution, with `J^T J` at it (for parameter uncertainties).
#[derive(Debug, Clone)]
pub struct Solution<S> {
    /// The optimised state.
    pub state: S,
    /// How it went.
    pub report: Report,
    /// `J^T J` at the solution, row-major `dim x dim`.
    pub jtj: Vec<f64>,
}

impl<S> Solution<S> {
    /// Standard deviations of the first `count` parameters: `sqrt(diag((J^T J)^-1) * sigma^2)`
    /// with `sigma^2` the residual variance. `None` when `J^T J` is singular.
    pub fn std_devs(&self, count: usize) -> Option<Vec<f64>> {
        let n = (self.jtj.len() as f64).sqrt() as usize;
        let dof = self.report.residuals.saturating_sub(n).max(1) as f64;
        let sigma2 = self.report.final_cost / dof;
        let l = cholesky(&self.jtj, n)?;
        Some(
            (0..count.min(n))
                .map(|k| {
                    let mut e = vec![0.0; n];
                    e[k] = 1.0;
                    (cholesky_solve(&l, n, &e)[k] * sigma2).max(0.0).sqrt()
                })
                .collect(),
        )
    }
}

fn jacobian<P: Problem>(p: &P, s: &P::State, m: usize, jac: &mut [f64], scratch: &mut (Vec<f64>, Vec<f64>)) {
    let n = p.dim();
    let mut delta = vec![0.0; n];
    for k in 0..n {
        let h = p.step(k);
        delta[k] = h;
        scratch.0.clear();
        p.residuals(&p.retract(s, &delta), &mut scratch.0);
        delta[k] = -h;
        scratch.1.clear();
        p.residuals(&p.retract(s, &delta), &mut scratch.1);
        delta[k] = 0.0;
        for i in 0..m {
            jac[i * n + k] = (scratch.0[i] - scratch.1[i]) / (2.0 * h);
        }
    }
}

/// `J^T J` and `J^T r` of the row-major `m x n` Jacobian, accumulated row by row.
fn normal_equations(jac: &[f64], r: &[f64], n: usize, jtj: &mut [f64], jtr: &mut [f64]) {
    jtj.fill(0.0);
    jtr.fill(0.0);
    for (row, ri) in jac.chunks_exact(n).zip(r) {
        for a in 0..n {
            let ja = row[a];
            if ja == 0.0 {
                continue;
            }
            jtr[a] += ja * ri;
            for b in a..n {
                jtj[a * n + b] += ja * row[b];
            }
        }
    }
    for a in 0..n {
        for b in 0..a {
            jtj[a * n + b] = jtj[b * n + a];
        }
    }
}

/// Minimises the sum of squared residuals from `s0`.
pub fn solve<P: Problem>(p: &P, s0: P::State, max_iterations: usize) -> Solution<P::State> {
    let n = p.dim();
    let mut s = s0;
    let mut r = Vec::new();
    p.residuals(&s, &mut r);
    let m = r.len();
    let cost = |r: &[f64]| r.iter().map(|v| v * v).sum::<f64>();
    let initial_cost = cost(&r);
    let mut current = initial_cost;
    let mut jac = vec![0.0; m * n];
    let mut jtj = vec![0.0; n * n];
    let mut scratch = (Vec::with_capacity(m), Vec::with_capacity(m));
    let mut lambda = 1e-3;
    let mut iterations = 0;
    let mut converged = false;
    let mut trial = Vec::with_capacity(m);
    let mut fresh = true;
    let mut jtr = vec![0.0; n];
    while iterations < max_iterations {
        if fresh {
            jacobian(p, &s, m, &mut jac, &mut scratch);
            normal_equations(&jac, &r, n, &mut jtj, &mut jtr);
            fresh = false;
        }
        iterations += 1;
        let mut damped = jtj.clone();
        for k in 0..n {
            damped[k * n + k] += lambda * jtj[k * n + k].max(1e-12);
        }
        let Some(l) = cholesky(&damped, n) else {
            lambda *= 10.0;
            if lambda > 1e12 {
                break;
            }
            continue;
        };
        let delta: Vec<f64> = cholesky_solve(&l, n, &jtr).into_iter().map(|v| -v).collect();
        let candidate = p.retract(&s, &delta);
        trial.clear();
        p.residuals(&candidate, &mut trial);
        let c = cost(&trial);
        if c.is_finite() && c < current {
            let gain = (current - c) / current.max(1e-300);
            s = candidate;
            std::mem::swap(&mut r, &mut trial);
            current = c;
            lambda = (lambda * 0.3).max(1e-12);
            fresh = true;
            let step_small = delta.iter().enumerate().all(|(k, d)| d.abs() < 1e-3 * p.step(k));
            if gain < 1e-12 || step_small {
                converged = true;
                break;
            }
        } else {
            lambda *= 10.0;
            if lambda > 1e12 {
                converged = true; // no step lowers the cost: a minimum to numerical precision
                break;
            }
        }
    }
    if fresh {
        jacobian(p, &s, m, &mut jac, &mut scratch);
        normal_equations(&jac, &r, n, &mut jtj, &mut jtr);
    }
    Solution {
        state: s,
        report: Report { iterations, initial_cost, final_cost: current, residuals: m, converged },
        jtj,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Fits y = a * exp(b * x) to exact data.
    struct Exp(Vec<(f64, f64)>);
    impl Problem for Exp {
        type State = [f64; 2];
        fn dim(&self) -> usize {
            2
        }
        fn residuals(&self, s: &[f64; 2], out: &mut Vec<f64>) {
            out.extend(self.0.iter().map(|(x, y)| s[0] * (s[1] * x).exp() - y));
        }
        fn retract(&self, s: &[f64; 2], d: &[f64]) -> [f64; 2] {
            [s[0] + d[0], s[1] + d[1]]
        }
        fn step(&self, _k: usize) -> f64 {
            1e-6
        }
    }

    #[test]
    fn fits_an_exponential() {
        let data = (0..20).map(|i| f64::from(i) * 0.1).map(|x| (x, 2.5 * (-1.3 * x).exp())).collect();
        let sol = solve(&Exp(data), [1.0, 0.0], 100);
        assert!((sol.state[0] - 2.5).abs() < 1e-6 && (sol.state[1] + 1.3).abs() < 1e-6, "{:?}", sol.state);
        assert!(sol.report.converged && sol.report.final_cost < 1e-12);
    }
}
