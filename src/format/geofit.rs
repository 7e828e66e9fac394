//! The scene's geographic fit (manifest version 12, `crs.fit`): lon/lat ↔
//! scene-relative metres as two pairs of Chebyshev polynomials, fitted by the
//! bake from the exact projection (proj4rs) over a box around the scene.
//!
//! Why: the browser needs lon/lat for geographic cameras, shareable links,
//! the sun at a date and XYZ imagery, but proj4rs (every projection, its
//! ellipsoid and datum tables) was 55 KB of the viewer's 427 KB gzipped wasm
//! (issue 47). A projection is smooth over a scene, so a tensor-product
//! Chebyshev interpolant of degree 3–12 on Chebyshev nodes matches it to
//! under a millimetre (Trefethen, *Approximation Theory and Approximation
//! Practice*, 2013, ch. 3 and 8: interpolation in Chebyshev points converges
//! geometrically for analytic functions); the bake raises the degree until
//! the fit is within [`FIT_TOLERANCE_M`] on a check grid both ways and
//! records the error it measured. Outside the box a fit continues along its
//! tangent plane at the box's edge (no wild polynomial growth).
//!
//! Layout: `to_local[k]` (k = 0 for x, 1 for y) holds `(degree + 1)²`
//! coefficients `c[i·(degree+1) + j]` of `T_i(u)·T_j(v)`, u and v the
//! longitude and latitude mapped from the `geo` box to [−1, 1]; `to_geo[k]`
//! (k = 0 for lon, 1 for lat, degrees) the same over the `local` box.

use serde::{Deserialize, Serialize};

use super::error::{finite, Problem};

/// Highest degree a fit may have ((24 + 1)² = 625 coefficients a coordinate).
pub const MAX_DEGREE: u32 = 24;
/// The bake's goal for a fit's error, metres, on its check grid both ways.
pub const FIT_TOLERANCE_M: f64 = 0.001;
/// Degrees the bake tries, lowest first.
const DEGREES: [u32; 10] = [3, 4, 5, 6, 8, 10, 12, 16, 20, 24];
/// Check points per side of the box (its edges included).
const CHECK: usize = 24;
/// Metres of a degree of latitude (and of longitude at the equator), for errors.
const M_PER_DEG: f64 = 111_320.0;

const SIDE: usize = MAX_DEGREE as usize + 1;

/// lon/lat ↔ scene-relative x, y of one scene (see the module's documentation).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GeoFit {
    /// `[x0, y0, x1, y1]`: the box, metres relative to the scene origin, that
    /// `to_geo` covers.
    pub local: [f64; 4],
    /// `[lon0, lat0, lon1, lat1]`, degrees: the box `to_local` covers.
    pub geo: [f64; 4],
    /// Degree n of each polynomial in each variable.
    pub degree: u32,
    /// lon, lat → x, y (metres): `[x, y]`, `(n + 1)²` coefficients each.
    pub to_local: [Vec<f64>; 2],
    /// x, y → lon, lat (degrees): `[lon, lat]`, `(n + 1)²` coefficients each.
    pub to_geo: [Vec<f64>; 2],
    /// Largest distance, metres, between the fit and the exact projection that
    /// the bake measured on its check grid, both ways.
    pub error_m: f64,
}

impl GeoFit {
    /// Scene-relative (x, y) metres of `lon`, `lat` (degrees); `None` for
    /// non-finite input.
    #[must_use]
    pub fn to_local(&self, lon: f64, lat: f64) -> Option<(f64, f64)> {
        self.eval(&self.to_local, &self.geo, lon, lat)
    }

    /// (lon, lat) degrees of the scene-relative point (x, y); `None` for
    /// non-finite input.
    #[must_use]
    pub fn to_geo(&self, x: f64, y: f64) -> Option<(f64, f64)> {
        self.eval(&self.to_geo, &self.local, x, y)
    }

    /// Both coordinates of one direction's fit over the box `bx` at (a, b).
    fn eval(&self, c: &[Vec<f64>; 2], bx: &[f64; 4], a: f64, b: f64) -> Option<(f64, f64)> {
        let (u, v) = (unit(bx[0], bx[2], a), unit(bx[1], bx[3], b));
        let p = eval(c, self.degree as usize, u, v);
        (p.0.is_finite() && p.1.is_finite()).then_some(p)
    }

    /// Fits the projection of the scene-relative box `local` (`[x0, y0, x1,
    /// y1]`): `to_geo` and `to_local` are the exact projection both ways.
    /// Raises the degree until the fit is within [`FIT_TOLERANCE_M`] on a
    /// check grid; past [`MAX_DEGREE`] keeps the best fit (its `error_m` says
    /// how far it is).
    ///
    /// # Errors
    /// A message when the projection fails inside the box, the box is empty
    /// or not finite, or the box crosses the antimeridian or a pole.
    pub fn fit(
        local: [f64; 4],
        to_geo: &dyn Fn(f64, f64) -> Option<(f64, f64)>,
        to_local: &dyn Fn(f64, f64) -> Option<(f64, f64)>,
    ) -> Result<Self, String> {
        if !local.iter().all(|v| v.is_finite()) || local[2] <= local[0] || local[3] <= local[1] {
            return Err(format!("the box {local:?} is empty or not finite"));
        }
        // The lon/lat box around the local box's image.
        let mut geo = [f64::INFINITY, f64::INFINITY, f64::NEG_INFINITY, f64::NEG_INFINITY];
        for (x, y) in grid(&local, CHECK) {
            let (lon, lat) = to_geo(x, y).ok_or_else(|| format!("the projection fails at {x:.1}, {y:.1}"))?;
            geo = [geo[0].min(lon), geo[1].min(lat), geo[2].max(lon), geo[3].max(lat)];
        }
        if !geo.iter().all(|v| v.is_finite()) || geo[2] - geo[0] > 180.0 || geo[2] <= geo[0] || geo[3] <= geo[1] {
            return Err(format!("the scene's lon/lat box {geo:?} crosses the antimeridian or is empty"));
        }
        if geo[1] < -89.0 || geo[3] > 89.0 {
            return Err(format!("the scene's lon/lat box {geo:?} reaches a pole"));
        }
        let mut best: Option<Self> = None;
        for degree in DEGREES {
            let n = degree as usize;
            let fwd = interpolate(&geo, n, to_local, 1e-7)?;
            let inv = interpolate(&local, n, to_geo, 1e-12)?;
            let mut fit = Self { local, geo, degree, to_local: fwd, to_geo: inv, error_m: 0.0 };
            fit.error_m = fit.measure(to_geo, to_local)?;
            let done = fit.error_m <= FIT_TOLERANCE_M;
            if best.as_ref().is_none_or(|b| fit.error_m < b.error_m) {
                best = Some(fit);
            }
            if done {
                break;
            }
        }
        best.ok_or_else(|| "no fit".into())
    }

    /// Largest distance (metres) between the fit and the projection on a
    /// check grid that misses the nodes, both ways.
    fn measure(
        &self,
        to_geo: &dyn Fn(f64, f64) -> Option<(f64, f64)>,
        to_local: &dyn Fn(f64, f64) -> Option<(f64, f64)>,
    ) -> Result<f64, String> {
        let mut worst = 0.0f64;
        for (x, y) in grid(&self.local, CHECK) {
            let exact = to_geo(x, y).ok_or_else(|| format!("the projection fails at {x:.1}, {y:.1}"))?;
            let fit = self.to_geo(x, y).unwrap_or((f64::INFINITY, 0.0));
            let d = ((fit.0 - exact.0) * exact.1.to_radians().cos()).hypot(fit.1 - exact.1) * M_PER_DEG;
            worst = worst.max(d);
        }
        for (lon, lat) in grid(&self.geo, CHECK) {
            let exact = to_local(lon, lat).ok_or_else(|| format!("the projection fails at {lon:.6}, {lat:.6}"))?;
            let fit = self.to_local(lon, lat).unwrap_or((f64::INFINITY, 0.0));
            worst = worst.max((fit.0 - exact.0).hypot(fit.1 - exact.1));
        }
        Ok(if worst.is_nan() { f64::INFINITY } else { worst })
    }

    /// Checks a decoded fit: boxes finite and not empty, latitudes on the
    /// globe, the degree at most [`MAX_DEGREE`], `(degree + 1)²` finite
    /// coefficients in each list.
    pub(crate) fn validate(&self) -> Result<(), Problem> {
        for (i, v) in self.local.iter().chain(&self.geo).enumerate() {
            finite(format_args!("crs.fit box[{i}]"), *v)?;
        }
        if self.local[2] <= self.local[0] || self.local[3] <= self.local[1] {
            return Err(Problem::Invalid(format!("crs.fit.local {:?} is an empty box", self.local)));
        }
        let g = self.geo;
        if g[2] <= g[0] || g[3] <= g[1] || g[1] < -90.0 || g[3] > 90.0 || g[0] < -540.0 || g[2] > 540.0 {
            return Err(Problem::Invalid(format!("crs.fit.geo {g:?} is not a lon/lat box")));
        }
        if self.degree > MAX_DEGREE {
            return Err(Problem::Invalid(format!("crs.fit.degree {} exceeds {MAX_DEGREE}", self.degree)));
        }
        let len = (self.degree as usize + 1).pow(2);
        for (name, lists) in [("to_local", &self.to_local), ("to_geo", &self.to_geo)] {
            for (k, c) in lists.iter().enumerate() {
                if c.len() != len {
                    return Err(Problem::Invalid(format!(
                        "crs.fit.{name}[{k}] has {} coefficients, degree {} needs {len}",
                        c.len(),
                        self.degree
                    )));
                }
                for (i, v) in c.iter().enumerate() {
                    finite(format_args!("crs.fit.{name}[{k}][{i}]"), *v)?;
                }
            }
        }
        let e = finite("crs.fit.error_m", self.error_m)?;
        if e < 0.0 {
            return Err(Problem::Invalid(format!("crs.fit.error_m {e} is negative")));
        }
        Ok(())
    }
}

/// `value` mapped from [lo, hi] to [−1, 1].
fn unit(lo: f64, hi: f64, value: f64) -> f64 {
    (2.0 * value - (lo + hi)) / (hi - lo)
}

/// `count`² points spread evenly over `bx`, its edges included.
fn grid(bx: &[f64; 4], count: usize) -> impl Iterator<Item = (f64, f64)> + '_ {
    let at = move |lo: f64, hi: f64, k: usize| lo + (hi - lo) * k as f64 / (count - 1) as f64;
    (0..count).flat_map(move |j| (0..count).map(move |i| (at(bx[0], bx[2], i), at(bx[1], bx[3], j))))
}

/// The Chebyshev interpolant of degree `n` of `f` over `bx` (each output's
/// `(n + 1)²` coefficients), each coefficient rounded to a multiple of about
/// `quantum` so the manifest writes it short.
fn interpolate(
    bx: &[f64; 4],
    n: usize,
    f: &dyn Fn(f64, f64) -> Option<(f64, f64)>,
    quantum: f64,
) -> Result<[Vec<f64>; 2], String> {
    let count = n + 1;
    // Chebyshev points of the first kind, cos(π (k + ½) / (n + 1)).
    let angle = |k: usize| std::f64::consts::PI * (k as f64 + 0.5) / count as f64;
    let node = |lo: f64, hi: f64, k: usize| 0.5 * (lo + hi) + 0.5 * (hi - lo) * angle(k).cos();
    let mut values = vec![(0.0, 0.0); count * count];
    for l in 0..count {
        for k in 0..count {
            let (x, y) = (node(bx[0], bx[2], k), node(bx[1], bx[3], l));
            values[l * count + k] = f(x, y).ok_or_else(|| format!("the projection fails at {x:.6}, {y:.6}"))?;
        }
    }
    // c_ij = (2 − δ_i0)(2 − δ_j0) / (n + 1)² Σ_k Σ_l f(x_k, y_l) cos(i θ_k) cos(j θ_l)
    let decimals = (-quantum.log10()).round().max(0.0) as usize;
    let mut out = [vec![0.0; count * count], vec![0.0; count * count]];
    for i in 0..count {
        for j in 0..count {
            let (mut sx, mut sy) = (0.0, 0.0);
            for l in 0..count {
                for k in 0..count {
                    let w = (i as f64 * angle(k)).cos() * (j as f64 * angle(l)).cos();
                    let v = values[l * count + k];
                    sx += v.0 * w;
                    sy += v.1 * w;
                }
            }
            let scale = (if i == 0 { 1.0 } else { 2.0 }) * (if j == 0 { 1.0 } else { 2.0 }) / (count * count) as f64;
            for (list, s) in out.iter_mut().zip([sx, sy]) {
                // Rounded in decimal so serde writes the short form (+ 0.0: no "-0.0").
                list[i * count + j] = format!("{:.*}", decimals, s * scale).parse().unwrap_or(s * scale) + 0.0;
            }
        }
    }
    Ok(out)
}

/// T_0..T_n at `u` and their derivatives (T_k' = k U_{k−1}).
fn basis(n: usize, u: f64) -> ([f64; SIDE], [f64; SIDE]) {
    let (mut t, mut d) = ([0.0; SIDE], [0.0; SIDE]);
    t[0] = 1.0;
    if n >= 1 {
        t[1] = u;
        d[1] = 1.0;
    }
    // U_{k−1} by its own recurrence, U_{−1} = 0, U_0 = 1.
    let (mut u2, mut u1) = (0.0, 1.0);
    for k in 2..=n {
        t[k] = 2.0 * u * t[k - 1] - t[k - 2];
        let uk = 2.0 * u * u1 - u2;
        d[k] = k as f64 * uk;
        (u2, u1) = (u1, uk);
    }
    (t, d)
}

/// Both fitted coordinates at (u, v) (the basis computed once for the two);
/// outside [−1, 1]² along the tangent plane at the nearest point of the square.
fn eval(c: &[Vec<f64>; 2], n: usize, u: f64, v: f64) -> (f64, f64) {
    let n = n.min(SIDE - 1);
    let (uc, vc) = (u.clamp(-1.0, 1.0), v.clamp(-1.0, 1.0));
    let ((tu, du), (tv, dv)) = (basis(n, uc), basis(n, vc));
    let one = |c: &[f64]| {
        let (mut f, mut fu, mut fv) = (0.0, 0.0, 0.0);
        for i in 0..=n {
            for j in 0..=n {
                let cij = c.get(i * (n + 1) + j).copied().unwrap_or(0.0);
                f += cij * tu[i] * tv[j];
                fu += cij * du[i] * tv[j];
                fv += cij * tu[i] * dv[j];
            }
        }
        f + fu * (u - uc) + fv * (v - vc)
    };
    (one(&c[0]), one(&c[1]))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A made-up smooth map (a little curvature in each direction) and its
    /// inverse by Newton steps: the fit does not need proj4rs to be tested.
    fn fwd(lon: f64, lat: f64) -> Option<(f64, f64)> {
        let (a, b) = (lon - 5.0, lat - 52.0);
        Some((70_000.0 * a + 300.0 * a * b + 20.0 * b * b, 111_000.0 * b + 150.0 * a * a + 5.0 * (a * b).sin()))
    }

    fn inv(x: f64, y: f64) -> Option<(f64, f64)> {
        let (mut lon, mut lat) = (5.0 + x / 70_000.0, 52.0 + y / 111_000.0);
        for _ in 0..30 {
            let (fx, fy) = fwd(lon, lat)?;
            let h = 1e-7;
            let (ax, ay) = fwd(lon + h, lat)?;
            let (bx, by) = fwd(lon, lat + h)?;
            let (j00, j01, j10, j11) = ((ax - fx) / h, (bx - fx) / h, (ay - fy) / h, (by - fy) / h);
            let det = j00 * j11 - j01 * j10;
            let (ex, ey) = (x - fx, y - fy);
            lon += (j11 * ex - j01 * ey) / det;
            lat += (j00 * ey - j10 * ex) / det;
        }
        Some((lon, lat))
    }

    #[test]
    fn fits_a_smooth_map_to_a_millimetre_and_extrapolates_along_the_edge() {
        let fit = GeoFit::fit([-20_000.0, -15_000.0, 25_000.0, 30_000.0], &inv, &fwd).unwrap();
        assert!(fit.error_m <= FIT_TOLERANCE_M, "{}", fit.error_m);
        assert!(fit.degree <= 6, "degree {}", fit.degree);
        fit.validate().unwrap();
        // Off the nodes and check grid.
        for (lon, lat) in [(5.013, 52.007), (4.81, 51.9), (5.2, 52.2)] {
            let (x, y) = fit.to_local(lon, lat).unwrap();
            let (ex, ey) = fwd(lon, lat).unwrap();
            assert!((x - ex).hypot(y - ey) < 0.002, "{lon} {lat}: {x} {y} vs {ex} {ey}");
            let (lon2, lat2) = fit.to_geo(ex, ey).unwrap();
            assert!((lon2 - lon).abs() < 1e-7 && (lat2 - lat).abs() < 1e-7);
        }
        // Beyond the box: continuous at the edge, then close to the map's tangent.
        let edge = fit.geo[2];
        let (a, _) = fit.to_local(edge - 1e-9, 52.0).unwrap();
        let (b, _) = fit.to_local(edge + 1e-9, 52.0).unwrap();
        assert!((a - b).abs() < 1e-3, "{a} {b}");
        let far = fit.to_local(edge + 1.0, 52.0).unwrap();
        let exact = fwd(edge + 1.0, 52.0).unwrap();
        assert!((far.0 - exact.0).abs() < 500.0, "{far:?} {exact:?}");
        assert!(fit.to_local(f64::NAN, 52.0).is_none());
        // The manifest's text round-trips exactly.
        let text = serde_json::to_string(&fit).unwrap();
        assert_eq!(serde_json::from_str::<GeoFit>(&text).unwrap(), fit);
    }

    #[test]
    fn refuses_hostile_fits_and_boxes() {
        let fit = GeoFit::fit([0.0, 0.0, 1000.0, 1000.0], &inv, &fwd).unwrap();
        let mut bad = fit.clone();
        bad.degree = MAX_DEGREE + 1;
        assert!(bad.validate().is_err());
        let mut bad = fit.clone();
        bad.to_geo[1].pop();
        assert!(bad.validate().unwrap_err().to_string().contains("to_geo[1]"));
        let mut bad = fit.clone();
        bad.to_local[0][3] = f64::NAN;
        assert!(bad.validate().is_err());
        let mut bad = fit.clone();
        bad.geo = [0.0, 10.0, 1.0, 95.0];
        assert!(bad.validate().is_err());
        let mut bad = fit;
        bad.local = [5.0, 0.0, 5.0, 1.0];
        assert!(bad.validate().is_err());
        assert!(GeoFit::fit([0.0, 0.0, f64::NAN, 1.0], &inv, &fwd).is_err());
        assert!(GeoFit::fit([0.0, 0.0, 1.0, 1.0], &|_, _| None, &fwd).is_err());
    }
}
