//! Canopy height model → trees (issue 45): individual trees found in a CHM
//! raster (heights above ground, a GeoTIFF read as DEMs are).
//!
//! 1. **Smoothing**: a 3 × 3 Gaussian (1-2-1) so a crown's rough surface has
//!    one top, not several.
//! 2. **Tree tops**: local maxima with a variable window (Popescu & Wynne 2004,
//!    "Seeing the trees in the forest", PE&RS 70(5): the window grows with the
//!    height at its centre, as crowns do): a pixel of at least `min_height` is a
//!    top where no pixel within `window(h)/2` of it (and none of its eight
//!    neighbours) is higher (ties: the first in row order). `window(h) = a + b·h` metres, by default 1.0 + 0.12 h
//!    (3.4 m at 20 m, 5.8 m at 40 m).
//! 3. **Crowns**: marker-controlled watershed (priority flood from the tops,
//!    highest first): a pixel joins the crown of the neighbour it is reached
//!    from if it is no higher than that neighbour (downhill from the top), at
//!    least half the top's height (a crown's base; lower is gap or understorey),
//!    at least `min_height`, and within `0.6·h` of the top (a crown is not wider
//!    than about its height). Crown diameter: that of the circle of the crown's
//!    area.
//!
//! What it cannot see: trees under closed canopy (understorey, suppressed
//! stems — a CHM is the top surface), tops merged in dense young stands
//! narrower than a window, and crowns cut at the raster's edge.

use anyhow::{bail, Result};
use std::collections::BinaryHeap;

use super::dem::Dem;

/// How trees are found.
#[derive(Debug, Clone)]
pub struct ChmOptions {
    /// Lowest tree top, m.
    pub min_height: f64,
    /// The window's width at height 0, m.
    pub window_a: f64,
    /// The window's growth per metre of height.
    pub window_b: f64,
    /// The species label of every tree found (the library's tree for it)
    /// outside the stands of `species_stands`.
    pub species: String,
    /// A stand map in the CHM's CRS whose stands give the species of the
    /// trees found in them (drawn by their shares) and their `stand` attribute.
    pub species_stands: Option<(std::path::PathBuf, std::sync::Arc<super::stands::StandOptions>)>,
    /// The raster is a surface model (`--dsm`): the CHM is it minus these DEMs.
    pub ground: Vec<std::path::PathBuf>,
    /// A leaf-type raster in the CHM's CRS (Copernicus HRL Dominant Leaf Type
    /// codes: 1 broadleaved, 2 coniferous) for the trees outside every stand.
    pub leaf_type: Option<std::path::PathBuf>,
    /// Points with a species (any placements file) naming the trees found
    /// within their crown, before stands and leaf types.
    pub species_points: Option<std::path::PathBuf>,
}

impl Default for ChmOptions {
    fn default() -> Self {
        Self {
            min_height: 2.0,
            window_a: 1.0,
            window_b: 0.12,
            species: "broadleaf".into(),
            species_stands: None,
            ground: Vec::new(),
            leaf_type: None,
            species_points: None,
        }
    }
}

/// One tree found.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ChmTree {
    /// Map x, y of its top (the pixel's centre).
    pub xy: [f64; 2],
    /// Its height, m (the CHM at its top, unsmoothed).
    pub height_m: f32,
    /// Its crown's diameter, m (the circle of its area).
    pub crown_m: f32,
}

/// The most pixels a CHM may have (a 1 m CHM of 400 km²).
pub const MAX_CHM_PIXELS: u64 = 400_000_000;

/// Turns a digital surface model (the canopy's top where there are trees, the
/// ground elsewhere) into a CHM: at each pixel's centre the first of `dems`
/// with data there (bilinear) is taken off, heights under the ground (noise)
/// become 0, pixels without ground no data. Returns how many pixels had no ground.
///
/// # Errors
/// A DEM in another CRS than the DSM's (by their GeoKeys), or one that covers
/// none of the DSM.
pub fn subtract_ground(dsm: &mut Dem, dems: &[(std::path::PathBuf, Dem)]) -> Result<u64> {
    for (path, dem) in dems {
        if let (Some(a), Some(b)) = (dsm.epsg, dem.epsg) {
            if a != b {
                bail!("DEM {} is in EPSG:{b}, the DSM in EPSG:{a}: give them in one CRS", path.display());
            }
        }
    }
    let (w, h) = (dsm.width as usize, dsm.height as usize);
    let mut missing = 0u64;
    for r in 0..h {
        let y = dsm.y0 + r as f64 * dsm.dy;
        for c in 0..w {
            let x = dsm.x0 + c as f64 * dsm.dx;
            let v = &mut dsm.heights[r * w + c];
            match dems.iter().find_map(|(_, d)| d.sample(x, y)) {
                Some(g) if v.is_finite() => *v = (*v - g).max(0.0),
                Some(_) => {}
                None => {
                    missing += 1;
                    *v = f32::NAN;
                }
            }
        }
    }
    if missing == (w * h) as u64 {
        bail!("no --dem has ground under any of the DSM's pixels (do they cover the same place, in the same CRS?)");
    }
    Ok(missing)
}

/// Finds the trees of a CHM.
///
/// # Errors
/// A CHM larger than [`MAX_CHM_PIXELS`], or whose pixels are not square
/// metres-sized steps (a CHM in degrees).
pub fn find_trees(chm: &Dem, options: &ChmOptions) -> Result<Vec<ChmTree>> {
    let (w, h) = (chm.width as usize, chm.height as usize);
    if (w as u64) * (h as u64) > MAX_CHM_PIXELS {
        bail!("{w} × {h} pixels: past {MAX_CHM_PIXELS}; cut the CHM into tiles");
    }
    let pixel = chm.dx.abs();
    if !(pixel > 0.01 && pixel < 100.0) || (chm.dy.abs() - pixel).abs() > 0.01 * pixel {
        bail!(
            "pixels of {} × {} map units: a CHM needs square pixels in metres (0.01–100 m; a CHM in degrees must be \
             reprojected)",
            chm.dx,
            chm.dy
        );
    }
    // Heights above ground: a DEM, centimetres or an undeclared nodata would
    // make windows hundreds of metres wide (and no trees).
    let mut sample: Vec<f32> =
        chm.heights.iter().step_by((chm.heights.len() / 100_000).max(1)).copied().filter(|h| h.is_finite()).collect();
    if !sample.is_empty() {
        let k = (sample.len() * 99 / 100).min(sample.len() - 1);
        let p99 = *sample.select_nth_unstable_by(k, f32::total_cmp).1;
        if p99 > 130.0 {
            bail!(
                "1 % of its heights are above {p99:.0} m: not heights above ground in metres (a DEM? centimetres? an \
                 undeclared nodata value?)"
            );
        }
    }
    let raw = |i: usize| -> f64 {
        let v = f64::from(chm.heights[i]);
        if v.is_finite() {
            v
        } else {
            0.0
        }
    };
    // 1. Smoothing.
    let mut smooth = vec![0f32; w * h];
    for r in 0..h {
        for c in 0..w {
            let (mut sum, mut weight) = (0.0, 0.0);
            for dr in -1i64..=1 {
                for dc in -1i64..=1 {
                    let (rr, cc) = (r as i64 + dr, c as i64 + dc);
                    if rr < 0 || cc < 0 || rr >= h as i64 || cc >= w as i64 {
                        continue;
                    }
                    let k = f64::from((2 - dr.abs() as i32) * (2 - dc.abs() as i32));
                    sum += k * raw(rr as usize * w + cc as usize);
                    weight += k;
                }
            }
            smooth[r * w + c] = (sum / weight) as f32;
        }
    }
    // 2. Tops.
    let window = |height: f64| options.window_a + options.window_b * height;
    let mut tops: Vec<usize> = Vec::new();
    for r in 0..h {
        for c in 0..w {
            let i = r * w + c;
            let v = smooth[i];
            if f64::from(v) < options.min_height {
                continue;
            }
            // At least the 3 × 3 neighbourhood, whatever the window's width.
            let radius = (0.5 * window(f64::from(v)) / pixel).max(1.5);
            let reach = radius.ceil() as i64;
            let mut top = true;
            'window: for dr in -reach..=reach {
                for dc in -reach..=reach {
                    if (dr == 0 && dc == 0) || ((dr * dr + dc * dc) as f64) > radius * radius {
                        continue;
                    }
                    let (rr, cc) = (r as i64 + dr, c as i64 + dc);
                    if rr < 0 || cc < 0 || rr >= h as i64 || cc >= w as i64 {
                        continue;
                    }
                    let j = rr as usize * w + cc as usize;
                    if smooth[j] > v || (smooth[j] == v && j < i) {
                        top = false;
                        break 'window;
                    }
                }
            }
            if top {
                tops.push(i);
            }
        }
    }
    // 3. Crowns: a priority flood from the tops.
    const NONE: u32 = u32::MAX;
    let mut label = vec![NONE; w * h];
    let mut heap: BinaryHeap<(u32, u32, u32)> = BinaryHeap::new(); // (height in mm, pixel, tree)
    let mm = |v: f32| (f64::from(v.max(0.0)) * 1000.0) as u32;
    for (t, &i) in tops.iter().enumerate() {
        label[i] = t as u32;
        heap.push((mm(smooth[i]), i as u32, t as u32));
    }
    let mut area = vec![0u64; tops.len()];
    while let Some((_, i, t)) = heap.pop() {
        let i = i as usize;
        area[t as usize] += 1;
        let top = tops[t as usize];
        let top_h = f64::from(smooth[top]);
        let (tr, tc) = ((top / w) as f64, (top % w) as f64);
        let (r, c) = (i / w, i % w);
        for (dr, dc) in [(-1i64, 0i64), (1, 0), (0, -1), (0, 1)] {
            let (rr, cc) = (r as i64 + dr, c as i64 + dc);
            if rr < 0 || cc < 0 || rr >= h as i64 || cc >= w as i64 {
                continue;
            }
            let j = rr as usize * w + cc as usize;
            let v = f64::from(smooth[j]);
            let far = ((rr as f64 - tr).powi(2) + (cc as f64 - tc).powi(2)).sqrt() * pixel > 0.6 * top_h;
            if label[j] != NONE || v > f64::from(smooth[i]) || v < 0.5 * top_h || v < options.min_height || far {
                continue;
            }
            label[j] = t;
            heap.push((mm(smooth[j]), j as u32, t));
        }
    }
    Ok(tops
        .iter()
        .zip(&area)
        .map(|(&i, &a)| {
            let (r, c) = (i / w, i % w);
            ChmTree {
                xy: [chm.x0 + c as f64 * chm.dx, chm.y0 + r as f64 * chm.dy],
                // The CHM at the top; the smoothed value where it is a hole.
                height_m: if chm.heights[i].is_finite() { raw(i) as f32 } else { smooth[i] },
                crown_m: (2.0 * (a as f64 * pixel * pixel / std::f64::consts::PI).sqrt()) as f32,
            }
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;

    /// A CHM drawn from a known stem map: each crown a cap of its height at
    /// its stem, falling to 60 % at its radius; the surface the highest crown,
    /// roughened by ±0.3 m (a lidar canopy's leaves and gaps).
    fn draw(trees: &[([f64; 2], f64, f64)], size_m: f64, pixel: f64) -> Dem {
        let n = (size_m / pixel) as u32;
        let mut heights = vec![0f32; (n * n) as usize];
        let mut rng = Rng::new(5);
        for r in 0..n {
            for c in 0..n {
                let (x, y) = (f64::from(c) * pixel, size_m - f64::from(r) * pixel);
                let mut top = 0.0f64;
                for &([tx, ty], th, radius) in trees {
                    let d = ((x - tx).powi(2) + (y - ty).powi(2)).sqrt() / radius;
                    if d <= 1.0 {
                        top = top.max(th * (1.0 - 0.4 * d * d));
                    }
                }
                let rough = if top > 0.0 { 0.6 * (rng.f64() - 0.5) } else { 0.0 };
                heights[(r * n + c) as usize] = (top + rough) as f32;
            }
        }
        Dem {
            width: n,
            height: n,
            x0: 0.0,
            dx: pixel,
            y0: size_m,
            dy: -pixel,
            epsg: Some(32633),
            heights,
            nodata: None,
            layout: "test".into(),
        }
    }

    /// A stand of 60 crowns of 14–30 m (crown radius 0.12–0.16 of the
    /// height; stems at least `apart` × the sum of two radii apart: 0.9
    /// touching, 0.6 interpenetrating), and 12 small trees of 6–8 m under them.
    fn stem_map(apart: f64) -> Vec<([f64; 2], f64, f64)> {
        let mut rng = Rng::new(11);
        let mut trees: Vec<([f64; 2], f64, f64)> = Vec::new();
        while trees.len() < 60 {
            let p = [5.0 + rng.f64() * 90.0, 5.0 + rng.f64() * 90.0];
            let h = 14.0 + rng.f64() * 16.0;
            let radius = h * (0.12 + 0.04 * rng.f64());
            if trees
                .iter()
                .all(|(q, _, qr)| ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2)).sqrt() > apart * (radius + qr))
            {
                trees.push((p, h, radius));
            }
        }
        // Understorey: within an overstorey crown.
        for k in 0..12 {
            let (p, _, radius) = trees[k * 5];
            trees.push(([p[0] + 0.4 * radius, p[1]], 6.0 + rng.f64() * 2.0, 1.5));
        }
        trees
    }

    /// Found tops matched to the overstorey's stems (within 1.5 m, each once):
    /// (found, false positives, mean crown diameter error, mean height error
    /// in m, understorey found).
    fn score(truth: &[([f64; 2], f64, f64)], found: &[ChmTree]) -> (usize, usize, f64, f64, usize) {
        let over = &truth[..60];
        let mut matched = vec![false; over.len()];
        let (mut false_positives, mut crown_err, mut height_err) = (0, Vec::new(), Vec::new());
        let mut unmatched: Vec<[f64; 2]> = Vec::new();
        for t in found {
            let best = over
                .iter()
                .enumerate()
                .filter(|(k, _)| !matched[*k])
                .map(|(k, (p, _, _))| (k, ((t.xy[0] - p[0]).powi(2) + (t.xy[1] - p[1]).powi(2)).sqrt()))
                .min_by(|a, b| a.1.total_cmp(&b.1));
            match best {
                Some((k, d)) if d < 1.5 => {
                    matched[k] = true;
                    height_err.push((f64::from(t.height_m) - over[k].1).abs());
                    crown_err.push((f64::from(t.crown_m) - 2.0 * over[k].2).abs() / (2.0 * over[k].2));
                }
                _ => {
                    false_positives += 1;
                    unmatched.push(t.xy);
                }
            }
        }
        // An understorey tree is seen if a top no overstorey stem took is at it.
        let under = truth[60..]
            .iter()
            .filter(|(p, _, _)| unmatched.iter().any(|t| ((t[0] - p[0]).powi(2) + (t[1] - p[1]).powi(2)).sqrt() < 1.0))
            .count();
        let detected = matched.iter().filter(|m| **m).count();
        let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len().max(1) as f64;
        (detected, false_positives, mean(&crown_err), mean(&height_err), under)
    }

    #[test]
    fn trees_of_a_known_stem_map_are_found_in_its_chm() {
        // (crowns apart, pixel m) → at least this many of 60 found, at most this many false.
        for (apart, pixel, least, most_false, crown_tolerance) in
            [(0.9, 0.5, 57, 3, 0.2), (0.9, 1.0, 55, 3, 0.25), (0.6, 0.5, 50, 4, 0.35), (0.6, 1.0, 48, 4, 0.4)]
        {
            let truth = stem_map(apart);
            let found = find_trees(&draw(&truth, 100.0, pixel), &ChmOptions::default()).unwrap();
            let (detected, false_positives, crown_err, height_err, under) = score(&truth, &found);
            eprintln!(
                "CHM test: crowns {apart} apart, {pixel} m pixels: {detected}/60 found, {false_positives} false \
                 positives, crown diameter error {:.1} %, height error {height_err:.2} m, understorey {under}/12",
                crown_err * 100.0
            );
            assert!(height_err < 1.0, "height error {height_err} m");
            assert!(detected >= least, "{detected} of 60 found ({apart}, {pixel} m)");
            assert!(false_positives <= most_false, "{false_positives} false positives ({apart}, {pixel} m)");
            assert!(crown_err < crown_tolerance, "crown diameter error {crown_err} ({apart}, {pixel} m)");
            // The understorey under closed crowns is not seen: said, and tested.
            assert_eq!(under, 0);
        }
    }

    #[test]
    fn bad_chms_are_refused() {
        let mut chm = draw(&[([5.0, 5.0], 10.0, 2.0)], 10.0, 0.5);
        chm.dx = 0.00001; // degrees
        assert!(find_trees(&chm, &ChmOptions::default()).unwrap_err().to_string().contains("metres"));
        let mut flat = draw(&[], 10.0, 0.5);
        flat.heights.iter_mut().for_each(|h| *h = f32::NAN);
        assert!(find_trees(&flat, &ChmOptions::default()).unwrap().is_empty(), "holes are no trees");
    }

    /// A DSM less its DEM is the CHM: heights over sloping ground, noise under
    /// the ground clamped to 0, pixels without ground left out; a DEM in
    /// another CRS, or beside the DSM, refused.
    #[test]
    fn a_surface_model_less_the_ground_is_a_chm() {
        let chm = draw(&[([10.0, 10.0], 20.0, 3.0)], 20.0, 0.5);
        let slope = |x: f64, y: f64| 100.0 + 0.5 * x - 0.25 * y;
        let mut dsm = chm.clone();
        for r in 0..dsm.height as usize {
            for c in 0..dsm.width as usize {
                let (x, y) = (dsm.x0 + c as f64 * dsm.dx, dsm.y0 + r as f64 * dsm.dy);
                dsm.heights[r * dsm.width as usize + c] += slope(x, y) as f32 - 0.05;
            }
        }
        // The DEM: 1 m pixels over the west three quarters only.
        let mut dem = draw(&[], 15.0, 1.0);
        dem.y0 = 20.0;
        for r in 0..dem.height as usize {
            for c in 0..dem.width as usize {
                dem.heights[r * dem.width as usize + c] = slope(dem.x0 + c as f64, dem.y0 - r as f64) as f32;
            }
        }
        let dems = vec![(std::path::PathBuf::from("dem.tif"), dem.clone())];
        let missing = subtract_ground(&mut dsm, &dems).unwrap();
        assert!(missing > 0 && missing < u64::from(dsm.width * dsm.height) / 2, "{missing}");
        let (mut compared, mut holes) = (0, 0);
        for (k, (a, b)) in dsm.heights.iter().zip(&chm.heights).enumerate() {
            let (c, r) = (k % dsm.width as usize, k / dsm.width as usize);
            let (x, y) = (dsm.x0 + c as f64 * dsm.dx, dsm.y0 + r as f64 * dsm.dy);
            if a.is_nan() {
                holes += 1;
            } else if x < 13.5 && y > 6.5 {
                // (Within the DEM's outer pixel centres: bilinear is exact on a plane.)
                assert!(*a >= 0.0 && (a - b.max(0.05) + 0.05).abs() < 0.01, "{a} vs {b}");
                compared += 1;
            }
        }
        assert_eq!(holes, missing);
        assert!(compared > 500, "{compared}");
        let trees = find_trees(&dsm, &ChmOptions::default()).unwrap();
        assert_eq!(trees.len(), 1);
        assert!((trees[0].height_m - 20.0).abs() < 0.5, "{:?}", trees[0]);
        // Another CRS, or no ground under any pixel: refused.
        let mut other = dem.clone();
        other.epsg = Some(25833);
        let err = subtract_ground(&mut chm.clone(), &[(std::path::PathBuf::from("b.tif"), other)]).unwrap_err();
        assert!(err.to_string().contains("EPSG:25833"), "{err}");
        let mut away = dem;
        away.x0 = 5_000.0;
        let err = subtract_ground(&mut chm.clone(), &[(std::path::PathBuf::from("c.tif"), away)]).unwrap_err();
        assert!(err.to_string().contains("no --dem has ground"), "{err}");
    }
}
