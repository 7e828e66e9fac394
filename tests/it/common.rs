//! Helpers shared by the GPU tests: scene copies with edits, measures of images.

use std::path::Path;

use sylva::format::{Manifest, Tile};

/// Writes a copy of the scene `src` to `dst` (tiles listed flat) after
/// `edit_manifest` and `edit_tile` (each tile with its manifest entry).
pub fn rewritten_copy(
    src: &Path,
    dst: &Path,
    edit_manifest: impl FnOnce(&mut Manifest),
    mut edit_tile: impl FnMut(&mut Tile, &mut sylva::format::manifest::TileEntry),
) {
    let bytes = std::fs::read(src.join("scene.json")).unwrap();
    let mut m = Manifest::decode("scene.json", &bytes).unwrap();
    m.tiles = sylva::format::index::read_all_tiles(src, &m).unwrap();
    m.index = None;
    edit_manifest(&mut m);
    std::fs::create_dir_all(dst.join("tiles")).unwrap();
    std::fs::create_dir_all(dst.join("species")).unwrap();
    let species = m.species.len() as u32;
    for t in &mut m.tiles {
        let tb = std::fs::read(src.join(&t.url)).unwrap();
        let mut tile = Tile::decode(&t.url, &tb, species).unwrap();
        edit_tile(&mut tile, t);
        std::fs::write(dst.join(&t.url), tile.encode()).unwrap();
        std::fs::copy(src.join(&t.ids_url), dst.join(&t.ids_url)).unwrap();
    }
    for s in &m.species {
        std::fs::copy(src.join(&s.pack), dst.join(&s.pack)).unwrap();
    }
    if let Some(t) = &m.terrain {
        copy_dir(&src.join(&t.path), &dst.join(&t.path));
    }
    std::fs::write(dst.join("scene.json"), m.encode()).unwrap();
}

pub fn copy_dir(src: &Path, dst: &Path) {
    std::fs::create_dir_all(dst).unwrap();
    for e in std::fs::read_dir(src).unwrap() {
        let e = e.unwrap();
        if e.file_type().unwrap().is_dir() {
            copy_dir(&e.path(), &dst.join(e.file_name()));
        } else {
            std::fs::copy(e.path(), dst.join(e.file_name())).unwrap();
        }
    }
}

/// Share of pixels whose green stands out over red and blue by 8 levels or
/// 12 % of the green, whichever is less (shaded foliage is dark, and the
/// trees' own occlusion darkens it further; sky, ground and haze are not green).
pub fn foliage_share(img: &[u8]) -> f64 {
    let n = img.chunks_exact(4).filter(|p| sylva::metrics::is_foliage(p)).count();
    n as f64 / (img.len() / 4) as f64
}

/// Mean brightness (0–255, the mean of R, G and B) of the RGBA8 pixels in
/// `mask`, and how many there are.
pub fn tree_brightness(img: &[u8], mask: &[bool]) -> (f64, usize) {
    let (mut sum, mut n) = (0.0, 0usize);
    for (p, _) in img.chunks(4).zip(mask).filter(|(_, m)| **m) {
        sum += (f64::from(p[0]) + f64::from(p[1]) + f64::from(p[2])) / 3.0;
        n += 1;
    }
    (sum / n.max(1) as f64, n)
}
