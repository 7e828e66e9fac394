//! The pack cache (`--pack-cache DIR`): a species pack is a function of its
//! name, its model, the pack options, the bake tool that builds it and the GPU
//! that renders its billboards, impostors and error measures, so a bake that
//! finds a pack made from the same five in `DIR` takes it instead of building
//! it again. Building is most of a small bake's time (billboards and
//! impostors rendered on the GPU, ambient occlusion, cluster levels: seconds to
//! minutes a species); a forester re-baking an inventory with the same models
//! waits for the tiles only, and the test suite builds each pack once
//! (docs/ARCHITECTURE.md, "Tests").
//!
//! - **Key**: 128 bits of hash over the bake tool's executable (its bytes: any
//!   other build is another key), the GPU adapter the bake would render on
//!   (name, vendor, device, backend, driver and its version: another machine
//!   or a driver upgrade is another key), the species name, every field of the
//!   model and every field of [`PackOptions`]. The structs are destructured field by
//!   field below, so a field added to them fails to compile here until it is
//!   hashed (or said to leave packs alone).
//! - **Entries**: `DIR/<key>.pack`, the pack's bytes, written to a temporary
//!   file and renamed (a reader never sees half a pack). A cached pack is
//!   decoded and validated like any pack before it is used; one that does not
//!   decode is built again and replaced. Temporary files of a bake killed
//!   while writing are removed by the next writer of that key.
//! - **Concurrent bakes** (shards, parallel tests): `DIR/<key>.lock` is held
//!   while a pack is looked up and built, so a second bake of the same pack
//!   waits for the first and takes its result.
//!
//! Nothing is ever removed: delete `DIR` to free its space.

use std::fs::File;
use std::hash::{DefaultHasher, Hash, Hasher};
use std::io::Write;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result};

use crate::input::gltf_import::{ImportedMaterial, ImportedModel, ImportedVertex};
use crate::pack::PackOptions;

/// A folder of packs keyed by what they are built from.
pub struct PackCache {
    dir: PathBuf,
    /// Hash of the running executable: packs of another build are other keys.
    tool: [u64; 2],
}

/// An exclusive hold on one key, released when dropped.
pub struct KeyLock {
    _file: File,
}

impl PackCache {
    /// Opens (creating) the cache folder `dir`.
    ///
    /// # Errors
    /// When the folder cannot be created or the running executable read.
    pub fn open(dir: &Path) -> Result<Self> {
        std::fs::create_dir_all(dir).with_context(|| format!("--pack-cache {}: cannot create it", dir.display()))?;
        let exe = std::env::current_exe().context("--pack-cache: cannot find the running executable")?;
        let bytes = std::fs::read(&exe).with_context(|| format!("--pack-cache: cannot read {}", exe.display()))?;
        // (No adapter: nothing can be built either; the bake says so when it tries.)
        let adapter = pollster::block_on(sylva::render::GpuContext::headless_adapter()).ok().map(|(_, a)| a.get_info());
        let adapter = adapter.map(|i| {
            format!(
                "{}|{:x}|{:x}|{:?}|{:?}|{}|{}",
                i.name, i.vendor, i.device, i.device_type, i.backend, i.driver, i.driver_info
            )
        });
        Ok(Self {
            dir: dir.to_path_buf(),
            tool: hash128(|h| {
                bytes.hash(h);
                adapter.hash(h);
            }),
        })
    }

    /// The key of the pack of species `name` built from `model` with `options`.
    #[must_use]
    pub fn key(&self, name: &str, model: &ImportedModel, options: &PackOptions) -> String {
        let [a, b] = hash128(|h| {
            self.tool.hash(h);
            name.hash(h);
            hash_model(model, h);
            hash_options(options, h);
        });
        format!("{a:016x}{b:016x}")
    }

    /// Holds `key` until the returned lock is dropped (waiting while another
    /// bake holds it).
    ///
    /// # Errors
    /// When the lock file cannot be created or locked.
    pub fn lock(&self, key: &str) -> Result<KeyLock> {
        let path = self.dir.join(format!("{key}.lock"));
        let file = File::options()
            .create(true)
            .truncate(false)
            .write(true)
            .open(&path)
            .with_context(|| format!("--pack-cache: cannot create {}", path.display()))?;
        file.lock().with_context(|| format!("--pack-cache: cannot lock {}", path.display()))?;
        Ok(KeyLock { _file: file })
    }

    /// The cached bytes of `key`, if there are any (not yet validated).
    #[must_use]
    pub fn get(&self, key: &str) -> Option<Vec<u8>> {
        std::fs::read(self.entry(key)).ok()
    }

    /// Stores `bytes` as `key` (atomically: a temporary file renamed).
    ///
    /// # Errors
    /// When the entry cannot be written.
    pub fn put(&self, key: &str, bytes: &[u8]) -> Result<()> {
        let path = self.entry(key);
        // A bake killed while writing this key left its temporary file: the
        // caller holds the key's lock, so no live writer owns one.
        let stale = format!("{key}.tmp-");
        if let Ok(entries) = std::fs::read_dir(&self.dir) {
            for e in entries.flatten() {
                if e.file_name().to_str().is_some_and(|n| n.starts_with(&stale)) {
                    let _ = std::fs::remove_file(e.path());
                }
            }
        }
        let tmp = self.dir.join(format!("{key}.tmp-{}", std::process::id()));
        let write = || -> std::io::Result<()> {
            let mut f = File::create(&tmp)?;
            f.write_all(bytes)?;
            f.sync_all()?;
            std::fs::rename(&tmp, &path)
        };
        write().map_err(|e| {
            let _ = std::fs::remove_file(&tmp);
            anyhow::anyhow!("--pack-cache: cannot write {}: {e}", path.display())
        })
    }

    fn entry(&self, key: &str) -> PathBuf {
        self.dir.join(format!("{key}.pack"))
    }
}

/// Two independent 64-bit hashes of what `feed` writes (SipHash with fixed
/// keys: the same on every run of the same executable, which is all a key
/// needs: the executable is part of it).
fn hash128(feed: impl Fn(&mut DefaultHasher)) -> [u64; 2] {
    let mut a = DefaultHasher::new();
    feed(&mut a);
    let mut b = DefaultHasher::new();
    0x0053_796c_7661_u64.hash(&mut b); // "Sylva": a second, independent hash
    feed(&mut b);
    [a.finish(), b.finish()]
}

fn hash_f32s(values: &[f32], h: &mut DefaultHasher) {
    for v in values {
        v.to_bits().hash(h);
    }
}

fn hash_model(model: &ImportedModel, h: &mut DefaultHasher) {
    // Every field: a new one must be added here (or to the ignored ones).
    let ImportedModel { materials, vertices, triangles, notes: _, variants, autumn, genus } = model;
    autumn.hash(h);
    genus.hash(h);
    materials.len().hash(h);
    for m in materials {
        let ImportedMaterial { name, kind, base_color, alpha_cutoff, double_sided, texture, blended } = m;
        name.hash(h);
        (*kind as u8).hash(h);
        hash_f32s(base_color, h);
        alpha_cutoff.to_bits().hash(h);
        double_sided.hash(h);
        blended.hash(h);
        match texture {
            Some(t) => {
                (t.width(), t.height()).hash(h);
                t.as_raw().hash(h);
            }
            None => 0u8.hash(h),
        }
    }
    vertices.len().hash(h);
    for v in vertices {
        let ImportedVertex { position, normal, uv, color, material } = v;
        hash_f32s(&position.to_array(), h);
        hash_f32s(&normal.to_array(), h);
        hash_f32s(&uv.to_array(), h);
        hash_f32s(color, h);
        material.hash(h);
    }
    triangles.hash(h);
    variants.len().hash(h);
    for [position, normal] in variants.iter().flatten() {
        hash_f32s(&position.to_array(), h);
        hash_f32s(&normal.to_array(), h);
    }
}

fn hash_options(options: &PackOptions, h: &mut DefaultHasher) {
    let PackOptions {
        texture_size,
        billboard_angles,
        billboard_azimuths,
        billboard_size,
        simplified_level,
        clusters,
        cluster_tries,
        ao,
        far_tier,
        impostor_grid,
        impostor_size,
        cloud_planes,
        seasons,
        far_variants,
        // (How the pack is written, not what it holds: the cache keeps it as it is.)
        raw_packs: _,
        gpu_textures: _,
    } = options;
    (seasons, far_variants).hash(h);
    (texture_size, billboard_angles, billboard_azimuths, billboard_size).hash(h);
    (simplified_level, clusters, cluster_tries, ao).hash(h);
    (*far_tier as u8, impostor_grid, impostor_size, cloud_planes).hash(h);
}

#[cfg(test)]
mod tests {
    use super::*;

    fn model() -> ImportedModel {
        let vertex = |x: f32| ImportedVertex {
            position: glam::Vec3::new(x, 0.0, x),
            normal: glam::Vec3::Z,
            uv: glam::Vec2::ZERO,
            color: [1.0; 4],
            material: 0,
        };
        ImportedModel {
            materials: vec![ImportedMaterial {
                name: "leaf".into(),
                kind: sylva::format::pack::MaterialKind::Leaf,
                base_color: [0.2, 0.5, 0.1, 1.0],
                alpha_cutoff: 0.5,
                double_sided: true,
                texture: None,
                blended: false,
            }],
            vertices: vec![vertex(0.0), vertex(1.0), vertex(2.0)],
            triangles: vec![[0, 1, 2]],
            notes: Vec::new(),
            variants: Vec::new(),
            autumn: None,
            genus: None,
        }
    }

    #[test]
    fn keys_change_with_every_input_and_entries_round_trip() {
        let dir = std::env::temp_dir().join(format!("sylva-pack-cache-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let cache = PackCache::open(&dir).unwrap();
        let (m, o) = (model(), PackOptions::default());
        let key = cache.key("oak", &m, &o);
        assert_eq!(key, cache.key("oak", &m, &o), "the same inputs, the same key");
        assert_eq!(key.len(), 32);
        let mut other = m.clone();
        other.vertices[1].position.z += 1e-3;
        let mut texture = m.clone();
        texture.materials[0].texture = Some(image::RgbaImage::new(2, 2));
        let options = PackOptions { impostor_size: 16, ..PackOptions::default() };
        let keys = [
            cache.key("pine", &m, &o),
            cache.key("oak", &other, &o),
            cache.key("oak", &texture, &o),
            cache.key("oak", &m, &options),
            cache.key("oak", &m, &PackOptions { ao: false, ..PackOptions::default() }),
            cache.key("oak", &m, &PackOptions { seasons: false, ..PackOptions::default() }),
            cache.key("oak", &m, &PackOptions { far_variants: true, ..PackOptions::default() }),
            cache.key("oak", &ImportedModel { autumn: Some([200, 90, 30]), ..m.clone() }, &o),
        ];
        for k in &keys {
            assert_ne!(*k, key);
        }
        // Another build of the tool: another key.
        let other_tool = PackCache { dir: dir.clone(), tool: [1, 2] };
        assert_ne!(other_tool.key("oak", &m, &o), key);
        // Entries: none, then the bytes written. The lock is exclusive (a second
        // handle on the same key would block) and held per key.
        assert_eq!(cache.get(&key), None);
        let _held = cache.lock(&key).unwrap();
        let _other = cache.lock(&keys[0]).unwrap();
        let second = File::options().write(true).open(dir.join(format!("{key}.lock"))).unwrap();
        assert!(matches!(second.try_lock(), Err(std::fs::TryLockError::WouldBlock)), "the key's lock is exclusive");
        // A killed writer's temporary file is removed by the next write of its key.
        std::fs::write(dir.join(format!("{key}.tmp-999999")), b"half a pack").unwrap();
        cache.put(&key, b"pack bytes").unwrap();
        assert_eq!(cache.get(&key).as_deref(), Some(&b"pack bytes"[..]));
        assert!(std::fs::read_dir(&dir).unwrap().all(|e| !e.unwrap().file_name().to_string_lossy().contains(".tmp-")));
        let _ = std::fs::remove_dir_all(&dir);
    }
}
