//! Expectation–maximisation of a Gaussian mixture over 3D points (Clasen et al. 2010, §3.1),
//! built to be fast and robust: responsibilities are truncated spatially (each
//! point only sees its `neighbours` nearest components, found with a uniform
//! grid over the means), the E step works in the log domain, covariances are
//! regularised, both steps run in parallel with rayon, and components that lose
//! all their points are dropped.

use glam::{DMat3, DVec3};
use rayon::prelude::*;

/// Knobs of [`fit`].
#[derive(Debug, Clone, Copy)]
pub struct EmOptions {
    /// Components each point is scored against (the nearest by mean).
    pub neighbours: usize,
    /// Iteration cap.
    pub max_iterations: u32,
    /// Stop when the mean log-likelihood per point (nats) changes less than this
    /// (absolute, like scikit-learn's default).
    pub tolerance: f64,
    /// Added to every covariance's diagonal (m²): keeps single-point and coplanar
    /// components invertible.
    pub regularisation: f64,
}

impl Default for EmOptions {
    fn default() -> Self {
        Self { neighbours: 10, max_iterations: 100, tolerance: 1e-3, regularisation: 1e-6 }
    }
}

/// Iterations between refreshes of each point's nearest components.
const NEIGHBOUR_REFRESH: u32 = 4;

/// Upper bound of [`EmOptions::neighbours`].
pub const MAX_NEIGHBOURS: usize = 32;

/// A fitted mixture and the sparse fuzzy assignment of every point.
#[derive(Debug, Clone)]
pub struct Mixture {
    /// Component means.
    pub means: Vec<DVec3>,
    /// Component covariances.
    pub covariances: Vec<DMat3>,
    /// Mixing weights (sum 1).
    pub weights: Vec<f64>,
    /// Per point: (component, responsibility w_ij), responsibilities summing to 1.
    pub responsibilities: Vec<Vec<(u32, f32)>>,
    /// Mean log-likelihood per point at the end.
    pub log_likelihood: f64,
}

/// Uniform grid over component means for k-nearest queries.
struct Grid {
    alive: usize,
    lo: DVec3,
    cell: f64,
    dims: [usize; 3],
    cells: Vec<Vec<u32>>,
}

impl Grid {
    fn new(means: &[DVec3], alive: &[bool]) -> Self {
        let (mut lo, mut hi) = (DVec3::splat(f64::MAX), DVec3::splat(f64::MIN));
        let mut n = 0usize;
        for (m, _) in means.iter().zip(alive).filter(|(_, a)| **a) {
            lo = lo.min(*m);
            hi = hi.max(*m);
            n += 1;
        }
        if n == 0 {
            return Self { alive: 0, lo: DVec3::ZERO, cell: 1.0, dims: [1; 3], cells: vec![Vec::new()] };
        }
        let ext = (hi - lo).max(DVec3::splat(1e-9));
        // About two means per cell, over the axes the means actually spread along
        // (coplanar or collinear sets get 2D or 1D grids).
        let max_dim = ext.max_element();
        let spread: Vec<f64> = (0..3).map(|a| ext[a]).filter(|e| *e > max_dim * 1e-3).collect();
        let volume: f64 = spread.iter().product();
        let cell = (volume * 2.0 / n as f64).powf(1.0 / spread.len() as f64).max(max_dim / 64.0).max(1e-9);
        let dims = [0, 1, 2].map(|a| ((ext[a] / cell).floor() as usize + 1).min(64));
        let mut cells = vec![Vec::new(); dims[0] * dims[1] * dims[2]];
        let mut g = Self { alive: n, lo, cell, dims, cells: Vec::new() };
        for (i, m) in means.iter().enumerate() {
            if alive[i] {
                let c = g.coord(*m);
                cells[g.index(c)].push(i as u32);
            }
        }
        g.cells = cells;
        g
    }

    fn coord(&self, p: DVec3) -> [i64; 3] {
        [0, 1, 2].map(|a| (((p[a] - self.lo[a]) / self.cell).floor() as i64).clamp(0, self.dims[a] as i64 - 1))
    }

    fn index(&self, c: [i64; 3]) -> usize {
        (c[0] as usize) + self.dims[0] * ((c[1] as usize) + self.dims[1] * (c[2] as usize))
    }

    /// The `k` nearest means to `p` (fewer if fewer exist), unsorted.
    fn nearest(&self, p: DVec3, k: usize, means: &[DVec3], out: &mut Vec<(f64, u32)>) {
        out.clear();
        if k >= self.alive {
            for cell in &self.cells {
                out.extend(cell.iter().map(|&j| (means[j as usize].distance_squared(p), j)));
            }
            return;
        }
        let c = self.coord(p);
        let max_ring = self.dims.iter().max().copied().unwrap_or(1) as i64;
        for ring in 0..=max_ring {
            let range = |a: usize| (-ring).max(-c[a])..=ring.min(self.dims[a] as i64 - 1 - c[a]);
            for dz in range(2) {
                for dy in range(1) {
                    for dx in range(0) {
                        if dx.abs().max(dy.abs()).max(dz.abs()) != ring {
                            continue;
                        }
                        let q = [c[0] + dx, c[1] + dy, c[2] + dz];
                        for &j in &self.cells[self.index(q)] {
                            out.push((means[j as usize].distance_squared(p), j));
                        }
                    }
                }
            }
            if out.len() >= k {
                // Everything outside ring `ring` is at least `ring · cell` away.
                out.sort_unstable_by(|a, b| a.0.total_cmp(&b.0));
                let reach = ring as f64 * self.cell;
                if out[k - 1].0 <= reach * reach {
                    out.truncate(k);
                    return;
                }
            }
        }
        out.sort_unstable_by(|a, b| a.0.total_cmp(&b.0));
        out.truncate(k);
    }
}

/// Symmetric inverse and log-determinant of a covariance (with a fallback for
/// numerically singular ones).
fn inverse_logdet(c: DMat3) -> (DMat3, f64) {
    let det = c.determinant();
    if det.is_finite() && det > 1e-300 {
        (c.inverse(), det.ln())
    } else {
        let s = (c.x_axis.x + c.y_axis.y + c.z_axis.z).max(1e-12) / 3.0;
        (DMat3::from_diagonal(DVec3::splat(1.0 / s)), 3.0 * s.ln())
    }
}

/// Fits a mixture to `points` starting from components at `init_means`.
///
/// # Panics
/// Never for finite input; `points` and `init_means` must be non-empty.
#[must_use]
pub fn fit(points: &[DVec3], init_means: &[DVec3], opts: &EmOptions) -> Mixture {
    assert!(!points.is_empty() && !init_means.is_empty(), "EM needs points and components");
    let n = points.len();
    let k = init_means.len();
    let (lo, hi) =
        points.iter().fold((DVec3::splat(f64::MAX), DVec3::splat(f64::MIN)), |(l, h), p| (l.min(*p), h.max(*p)));
    let diag2 = (hi - lo).length_squared().max(1e-12);
    // Initial spread: the volume shared out between the components.
    let s0 = diag2 / (k as f64).powf(2.0 / 3.0) / 12.0 + opts.regularisation;
    let mut means = init_means.to_vec();
    let mut covs = vec![DMat3::from_diagonal(DVec3::splat(s0)); k];
    let mut weights = vec![1.0 / k as f64; k];
    let mut alive = vec![true; k];
    let reg = DMat3::from_diagonal(DVec3::splat(opts.regularisation.max(diag2 * 1e-12)));
    let mut resp: Vec<Vec<(u32, f32)>> = vec![Vec::new(); n];
    let mut ll_prev = f64::NEG_INFINITY;
    let mut ll = f64::NEG_INFINITY;
    let neighbours = opts.neighbours.clamp(1, MAX_NEIGHBOURS);
    const LOG_2PI: f64 = 1.837_877_066_409_345_5;
    // Each point's candidate components, refreshed every few iterations (the
    // means move little between refreshes; dead components are skipped).
    let mut cands: Vec<([u32; MAX_NEIGHBOURS], u8)> = vec![([0; MAX_NEIGHBOURS], 0); n];
    for it in 0..opts.max_iterations.max(1) {
        if it % NEIGHBOUR_REFRESH == 0 {
            let grid = Grid::new(&means, &alive);
            cands.par_iter_mut().zip(points.par_iter()).for_each_init(Vec::new, |near, (c, p)| {
                grid.nearest(*p, neighbours, &means, near);
                c.1 = near.len().min(MAX_NEIGHBOURS) as u8;
                for (slot, &(_, j)) in c.0.iter_mut().zip(near.iter()) {
                    *slot = j;
                }
            });
        }
        let pre: Vec<(DMat3, f64)> = covs.iter().map(|c| inverse_logdet(*c)).collect();
        let log_weights: Vec<f64> = weights.iter().map(|w| w.max(1e-300).ln()).collect();
        // E step (log domain, truncated to the nearest components).
        let lls: Vec<f64> = resp
            .par_iter_mut()
            .zip(points.par_iter().zip(cands.par_iter()))
            .map(|(r, (p, c))| {
                let mut logs = [(0u32, 0.0f64); MAX_NEIGHBOURS];
                let mut count = 0;
                for &j in &c.0[..usize::from(c.1)] {
                    if !alive[j as usize] {
                        continue;
                    }
                    let slot = &mut logs[count];
                    count += 1;
                    let (inv, logdet) = pre[j as usize];
                    let d = *p - means[j as usize];
                    let m = d.dot(inv * d);
                    *slot = (j, log_weights[j as usize] - 0.5 * (3.0 * LOG_2PI + logdet + m));
                }
                let logs = &logs[..count];
                let max = logs.iter().map(|l| l.1).fold(f64::NEG_INFINITY, f64::max);
                let sum: f64 = logs.iter().map(|l| (l.1 - max).exp()).sum();
                let lse = max + sum.ln();
                r.clear();
                for &(j, l) in logs {
                    let w = (l - lse).exp();
                    if w > 1e-6 {
                        r.push((j, w as f32));
                    }
                }
                if r.is_empty() {
                    // Every candidate died: stay with the first live component.
                    let j = alive.iter().position(|a| *a).unwrap_or(0) as u32;
                    r.push((j, 1.0));
                    return 0.0;
                }
                lse
            })
            .collect();
        ll = lls.iter().sum::<f64>() / n as f64;
        // M step: per component Σw, Σw x, Σw x xᵀ, summed over parallel chunks.
        let chunk = n.div_ceil(rayon::current_num_threads() * 4).max(256);
        let acc = resp
            .par_chunks(chunk)
            .zip(points.par_chunks(chunk))
            .map(|(rs, ps)| {
                let mut a = vec![(0.0f64, DVec3::ZERO, DMat3::ZERO); k];
                for (r, p) in rs.iter().zip(ps) {
                    for &(j, w) in r {
                        let w = f64::from(w);
                        let e = &mut a[j as usize];
                        e.0 += w;
                        e.1 += *p * w;
                        e.2 += outer(*p, *p) * w;
                    }
                }
                a
            })
            .reduce(
                || vec![(0.0, DVec3::ZERO, DMat3::ZERO); k],
                |mut a, b| {
                    for (x, y) in a.iter_mut().zip(b) {
                        x.0 += y.0;
                        x.1 += y.1;
                        x.2 += y.2;
                    }
                    a
                },
            );
        for (j, (sw, sx, sxx)) in acc.into_iter().enumerate() {
            if sw < 1e-6 {
                alive[j] = false;
                weights[j] = 0.0;
                continue;
            }
            let mu = sx / sw;
            let c = sxx * (1.0 / sw) - outer(mu, mu);
            means[j] = mu;
            covs[j] = symmetrise(c) + reg;
            weights[j] = sw / n as f64;
        }
        if (ll - ll_prev).abs() < opts.tolerance {
            break;
        }
        ll_prev = ll;
    }
    // Renumber the surviving components densely.
    let mut remap = vec![u32::MAX; k];
    let mut out = Mixture {
        means: Vec::new(),
        covariances: Vec::new(),
        weights: Vec::new(),
        responsibilities: Vec::new(),
        log_likelihood: ll,
    };
    for j in 0..k {
        if alive[j] {
            remap[j] = out.means.len() as u32;
            out.means.push(means[j]);
            out.covariances.push(covs[j]);
            out.weights.push(weights[j]);
        }
    }
    out.responsibilities = resp
        .into_iter()
        .map(|r| {
            let kept: Vec<(u32, f32)> = r
                .into_iter()
                .filter(|(j, _)| remap[*j as usize] != u32::MAX)
                .map(|(j, w)| (remap[j as usize], w))
                .collect();
            let s: f32 = kept.iter().map(|x| x.1).sum();
            kept.into_iter().map(|(j, w)| (j, w / s.max(1e-30))).collect()
        })
        .collect();
    out
}

/// `a bᵀ`.
#[must_use]
pub fn outer(a: DVec3, b: DVec3) -> DMat3 {
    DMat3::from_cols(a * b.x, a * b.y, a * b.z)
}

fn symmetrise(m: DMat3) -> DMat3 {
    (m + m.transpose()) * 0.5
}

/// Eigen-decomposition of a symmetric 3×3 matrix (cyclic Jacobi): eigenvalues
/// in descending order and the matching unit eigenvectors as columns
/// (a right-handed rotation).
#[must_use]
pub fn symmetric_eigen(m: DMat3) -> (DVec3, DMat3) {
    let mut a = m.to_cols_array_2d();
    let mut v = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    for _ in 0..50 {
        let off = a[0][1].powi(2) + a[0][2].powi(2) + a[1][2].powi(2);
        let scale = a[0][0].powi(2) + a[1][1].powi(2) + a[2][2].powi(2);
        if off <= 1e-30 * scale.max(1e-300) {
            break;
        }
        for (p, q) in [(0, 1), (0, 2), (1, 2)] {
            if a[p][q].abs() < 1e-300 {
                continue;
            }
            let theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
            let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
            let t = if theta == 0.0 { 1.0 } else { t };
            let c = 1.0 / (t * t + 1.0).sqrt();
            let s = t * c;
            // a ← Jᵀ a J, v ← v J (a is column-major but symmetric).
            for row in &mut a {
                let (arp, arq) = (row[p], row[q]);
                row[p] = c * arp - s * arq;
                row[q] = s * arp + c * arq;
            }
            let (row_p, row_q) = (a[p], a[q]);
            for r in 0..3 {
                a[p][r] = c * row_p[r] - s * row_q[r];
                a[q][r] = s * row_p[r] + c * row_q[r];
            }
            for row in &mut v {
                let (vp, vq) = (row[p], row[q]);
                row[p] = c * vp - s * vq;
                row[q] = s * vp + c * vq;
            }
        }
    }
    let vals = [a[0][0], a[1][1], a[2][2]];
    let mut order = [0usize, 1, 2];
    order.sort_by(|&i, &j| vals[j].total_cmp(&vals[i]));
    let col = |i: usize| DVec3::new(v[0][i], v[1][i], v[2][i]).normalize_or(DVec3::X);
    let (x, y) = (col(order[0]), col(order[1]));
    let z = x.cross(y).normalize_or(DVec3::Z);
    let y = z.cross(x);
    (DVec3::new(vals[order[0]], vals[order[1]], vals[order[2]]), DMat3::from_cols(x, y, z))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pack::clusters::Rng;

    fn gaussian(rng: &mut Rng) -> f64 {
        // Box–Muller.
        let u = rng.f64().max(1e-12);
        let v = rng.f64();
        (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
    }

    #[test]
    fn recovers_a_known_mixture() {
        let mut rng = Rng::new(7);
        let truth = [
            (DVec3::new(0.0, 0.0, 0.0), DVec3::new(1.0, 0.3, 0.3), 0.5),
            (DVec3::new(8.0, 1.0, 0.0), DVec3::new(0.4, 1.5, 0.4), 0.3),
            (DVec3::new(3.0, 7.0, 4.0), DVec3::new(0.5, 0.5, 2.0), 0.2),
        ];
        let mut points = Vec::new();
        for (mu, sd, w) in truth {
            for _ in 0..(6000.0 * w) as usize {
                points.push(
                    mu + DVec3::new(gaussian(&mut rng) * sd.x, gaussian(&mut rng) * sd.y, gaussian(&mut rng) * sd.z),
                );
            }
        }
        let init = vec![DVec3::new(1.0, 1.0, 1.0), DVec3::new(6.0, 0.0, 1.0), DVec3::new(2.0, 5.0, 2.0)];
        let m = fit(&points, &init, &EmOptions { neighbours: 3, max_iterations: 200, ..Default::default() });
        assert_eq!(m.means.len(), 3);
        for (mu, sd, w) in truth {
            let j = (0..3).min_by(|&a, &b| m.means[a].distance(mu).total_cmp(&m.means[b].distance(mu))).unwrap();
            assert!(m.means[j].distance(mu) < 0.1, "mean {:?} vs {mu:?}", m.means[j]);
            let var = DVec3::new(m.covariances[j].x_axis.x, m.covariances[j].y_axis.y, m.covariances[j].z_axis.z);
            assert!(((var.x.sqrt() - sd.x) / sd.x).abs() < 0.08, "sd {var:?} vs {sd:?}");
            assert!(((var.z.sqrt() - sd.z) / sd.z).abs() < 0.08, "sd {var:?} vs {sd:?}");
            assert!((m.weights[j] - w).abs() < 0.02, "weight {} vs {w}", m.weights[j]);
        }
        for r in &m.responsibilities {
            let s: f32 = r.iter().map(|x| x.1).sum();
            assert!((s - 1.0).abs() < 1e-4);
        }
    }

    #[test]
    fn degenerate_inputs_stay_finite() {
        let cases: Vec<Vec<DVec3>> = vec![
            vec![DVec3::new(1.0, 2.0, 3.0)],
            vec![DVec3::splat(4.0); 50],
            (0..100).map(|i| DVec3::new(i as f64, 0.0, 0.0)).collect(),
            (0..100).map(|i| DVec3::new((i % 10) as f64, (i / 10) as f64, 0.0)).collect(),
        ];
        for points in cases {
            let k = points.len().div_ceil(4);
            let init: Vec<DVec3> = points.iter().step_by(4).copied().collect();
            assert_eq!(init.len(), k);
            let m = fit(&points, &init, &EmOptions::default());
            assert!(!m.means.is_empty());
            assert!(m.log_likelihood.is_finite());
            for (mu, c) in m.means.iter().zip(&m.covariances) {
                assert!(mu.is_finite() && c.is_finite() && c.determinant() > 0.0);
            }
        }
    }

    #[test]
    fn eigen_of_known_matrix() {
        let r = DMat3::from_euler(glam::EulerRot::ZYX, 0.4, 0.9, -0.2);
        let m = r * DMat3::from_diagonal(DVec3::new(9.0, 4.0, 0.25)) * r.transpose();
        let (vals, vecs) = symmetric_eigen(m);
        assert!((vals - DVec3::new(9.0, 4.0, 0.25)).abs().max_element() < 1e-9, "{vals:?}");
        for i in 0..3 {
            assert!(vecs.col(i).dot(r.col(i)).abs() > 1.0 - 1e-9);
        }
        assert!((vecs.determinant() - 1.0).abs() < 1e-9);
        let (vals, _) = symmetric_eigen(DMat3::ZERO);
        assert_eq!(vals, DVec3::ZERO);
    }
}
