//! The output folder of a bake, `merge` or `demo`: written atomically, and
//! nothing removed that the bake did not write.
//!
//! The promise (docs/SECURITY.md): a bake removes only files that a bake wrote.
//! Each scene folder records the files its bake wrote in [`OWNED_LIST`]; a
//! re-bake replaces and removes only those. A folder holding anything else (the
//! inputs, a `thesis.txt`) is refused unless `--force`, which writes the scene
//! beside those files and keeps them. An `--out` that is a symbolic link is
//! followed: the scene is written where the link points, and the link stays.
//!
//! The new scene is written into a hidden folder inside `--out`
//! (`.sylva-tmp-PID`) and moved into place at the end, `scene.json` last: a
//! reader never sees a half-written scene as complete, and a failed bake leaves
//! the old scene as it was. Leftovers of an interrupted bake (Ctrl-C, kill -9)
//! are removed by the next bake into the same folder.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use serde::{Deserialize, Serialize};

/// The file, in a scene folder, that lists the files its bake wrote.
pub const OWNED_LIST: &str = ".sylva-bake-files.json";
/// Prefix of the hidden working folders of a running bake.
const TMP_PREFIX: &str = ".sylva-tmp-";

#[derive(Serialize, Deserialize)]
struct OwnedList {
    format: String,
    version: u32,
    /// Paths relative to the scene folder, `/`-separated, sorted.
    files: Vec<String>,
}

/// An output folder, checked and ready for [`OutDir::write`].
#[derive(Debug)]
pub struct OutDir {
    /// Where the scene goes (the target of `--out` when it is a link).
    real: PathBuf,
    /// As the user named it, for messages.
    named: PathBuf,
    /// Whether files the bake did not write may stay beside the scene.
    force: bool,
    /// Whether this run created the folder (removed again, if still empty,
    /// when the bake fails or stops before writing).
    created: bool,
}

impl Drop for OutDir {
    fn drop(&mut self) {
        if self.created {
            // Only an empty folder goes: one that a finished bake filled stays.
            let _ = std::fs::remove_dir(&self.real);
        }
    }
}

impl OutDir {
    /// Checks `out` before any long work: it is a folder or can be one; it
    /// holds no input and no file a bake did not write (unless `force`).
    /// Leftovers of interrupted bakes in it are removed.
    ///
    /// # Errors
    /// Every refusal names the folder and the files, and says what to do.
    pub fn prepare(out: &Path, inputs: &[&Path], force: bool, log: &dyn Fn(&str)) -> Result<OutDir> {
        let named = out.to_path_buf();
        let is_link = std::fs::symlink_metadata(out).is_ok_and(|m| m.file_type().is_symlink());
        let real = if is_link {
            let target = std::fs::canonicalize(out).with_context(|| {
                format!("--out {} is a symbolic link to a folder that does not exist", out.display())
            })?;
            log(&format!("--out {} is a link: writing the scene into {}", out.display(), target.display()));
            target
        } else {
            out.to_path_buf()
        };
        let created = match std::fs::metadata(&real) {
            Ok(m) if m.is_dir() => false,
            Ok(_) => bail!("--out {} exists and is not a folder", real.display()),
            Err(_) => {
                std::fs::create_dir_all(&real).with_context(|| format!("cannot create --out {}", real.display()))?;
                true
            }
        };
        let dir = OutDir { real, named, force, created };
        dir.remove_leftovers(log);
        let real_abs = std::fs::canonicalize(&dir.real)?;
        for input in inputs {
            if let Ok(input_abs) = std::fs::canonicalize(input) {
                if input_abs.starts_with(&real_abs) && !force {
                    bail!(
                        "--out {} holds the input {}: a bake never writes over its inputs; bake into another \
                         folder, or pass --force to write the scene beside them (they are kept)",
                        dir.named.display(),
                        input.display()
                    );
                }
            }
        }
        let foreign = dir.foreign()?;
        if !foreign.is_empty() && !force {
            bail!("{}", dir.foreign_message(&foreign));
        }
        let owned = dir.owned()?;
        if !owned.is_empty() {
            log(&format!(
                "replacing the scene in {}: the {} files of its earlier bake are replaced or removed{}",
                dir.named.display(),
                owned.len(),
                if foreign.is_empty() {
                    String::new()
                } else {
                    format!("; {} other files are kept (--force)", foreign.len())
                }
            ));
        }
        Ok(dir)
    }

    /// A hidden working folder inside the output, for bucket files.
    #[must_use]
    pub fn scratch(&self, what: &str) -> PathBuf {
        self.real.join(format!("{TMP_PREFIX}{}-{what}", std::process::id()))
    }

    /// Runs `write` into a hidden folder inside the output, then moves its
    /// files into place (`scene.json` last) and removes the files of the
    /// earlier bake that the new one did not write again.
    ///
    /// # Errors
    /// What `write` returns (the old scene is then left as it was), or a
    /// failure to move files, naming them.
    pub fn write<T>(self, write: impl FnOnce(&Path) -> Result<T>) -> Result<T> {
        let tmp = self.real.join(format!("{TMP_PREFIX}{}", std::process::id()));
        if tmp.exists() {
            std::fs::remove_dir_all(&tmp).with_context(|| format!("cannot remove {}", tmp.display()))?;
        }
        std::fs::create_dir(&tmp).with_context(|| format!("cannot write into --out {}", self.named.display()))?;
        let result = write(&tmp).and_then(|value| self.commit(&tmp).map(|()| value));
        let _ = std::fs::remove_dir_all(&tmp);
        result
    }

    fn commit(&self, tmp: &Path) -> Result<()> {
        // Checked again: a file may have appeared during a long bake.
        let foreign = self.foreign()?;
        if !foreign.is_empty() && !self.force {
            bail!("{}", self.foreign_message(&foreign));
        }
        let old = self.owned()?;
        let new = list_files(tmp)?;
        if let Some(taken) = new.iter().find(|rel| !old.contains(*rel) && self.real.join(rel).exists()) {
            bail!(
                "--out {} holds {taken}, which no bake wrote and the scene needs: it is kept; bake into another folder",
                self.named.display()
            );
        }
        // Record old and new first: a bake stopped half-way through the moves
        // still knows every file here that is its own.
        self.record(&old.union(&new).cloned().collect())?;
        let scene_json = "scene.json".to_string();
        let manifest = self.real.join(&scene_json);
        if manifest.exists() {
            std::fs::remove_file(&manifest).with_context(|| format!("cannot replace {}", manifest.display()))?;
        }
        for rel in new.iter().filter(|r| **r != scene_json).chain(new.get(&scene_json)) {
            let (from, to) = (tmp.join(rel), self.real.join(rel));
            if let Some(parent) = to.parent() {
                std::fs::create_dir_all(parent).with_context(|| format!("cannot create {}", parent.display()))?;
            }
            std::fs::rename(&from, &to).with_context(|| format!("cannot move the new {rel} into place"))?;
        }
        let mut dirs = BTreeSet::new();
        for rel in old.difference(&new) {
            let path = self.real.join(rel);
            match std::fs::remove_file(&path) {
                Ok(()) => {}
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
                Err(e) => return Err(e).with_context(|| format!("cannot remove the old {}", path.display())),
            }
            let mut p = Path::new(rel).parent();
            while let Some(d) = p.filter(|d| !d.as_os_str().is_empty()) {
                dirs.insert(d.to_path_buf());
                p = d.parent();
            }
        }
        // Folders the old scene used and the new one does not, if now empty
        // (deepest first; a folder holding anything else stays).
        for d in dirs.iter().rev() {
            let _ = std::fs::remove_dir(self.real.join(d));
        }
        self.record(&new)
    }

    fn record(&self, files: &BTreeSet<String>) -> Result<()> {
        let list = OwnedList { format: "sylva-bake-files".into(), version: 1, files: files.iter().cloned().collect() };
        let path = self.real.join(OWNED_LIST);
        let mut bytes = serde_json::to_vec_pretty(&list)?;
        bytes.push(b'\n');
        std::fs::write(&path, bytes).with_context(|| format!("cannot write {}", path.display()))
    }

    /// The files an earlier bake wrote here: its list, or for a scene baked
    /// before lists existed (a valid `scene.json`), `scene.json` and the
    /// files under `species/`, `tiles/` and `index/`.
    fn owned(&self) -> Result<BTreeSet<String>> {
        let list_path = self.real.join(OWNED_LIST);
        if let Ok(bytes) = std::fs::read(&list_path) {
            let list: OwnedList = serde_json::from_slice(&bytes)
                .with_context(|| format!("{} is not a list of baked files", list_path.display()))?;
            // Only plain relative names count: a doctored list cannot reach outside.
            return Ok(list
                .files
                .into_iter()
                .filter(|f| Path::new(f).components().all(|c| matches!(c, std::path::Component::Normal(_))))
                .collect());
        }
        let manifest = self.real.join("scene.json");
        let legacy =
            std::fs::read(&manifest).ok().is_some_and(|b| sylva::format::Manifest::decode("scene.json", &b).is_ok());
        if !legacy {
            return Ok(BTreeSet::new());
        }
        let mut owned: BTreeSet<String> = list_files(&self.real)?
            .into_iter()
            .filter(|f| ["species/", "tiles/", "index/"].iter().any(|d| f.starts_with(d)))
            .collect();
        owned.insert("scene.json".into());
        Ok(owned)
    }

    /// Files here that no bake wrote.
    fn foreign(&self) -> Result<Vec<String>> {
        let owned = self.owned()?;
        Ok(list_files(&self.real)?.into_iter().filter(|f| !owned.contains(f) && f != OWNED_LIST).collect())
    }

    fn foreign_message(&self, foreign: &[String]) -> String {
        let shown: Vec<&str> = foreign.iter().take(8).map(String::as_str).collect();
        format!(
            "--out {} holds {} file{} that no bake wrote ({}{}): a bake removes only files a bake wrote. Bake into a \
             new or empty folder, or pass --force to write the scene beside them (they are kept)",
            self.named.display(),
            foreign.len(),
            if foreign.len() == 1 { "" } else { "s" },
            shown.join(", "),
            if foreign.len() > shown.len() { ", …" } else { "" }
        )
    }

    /// Removes the working folders of bakes that are no longer running: here
    /// (`.sylva-tmp-PID…`) and beside the folder (`.NAME.tmp-PID`, the layout
    /// of earlier versions).
    fn remove_leftovers(&self, log: &dyn Fn(&str)) {
        let name = self.real.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
        let beside = format!(".{name}.tmp-");
        let parent = self.real.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
        for (dir, prefix) in [(self.real.as_path(), TMP_PREFIX), (parent, beside.as_str())] {
            let Ok(entries) = std::fs::read_dir(dir) else { continue };
            for entry in entries.flatten() {
                let file_name = entry.file_name().to_string_lossy().into_owned();
                let Some(rest) = file_name.strip_prefix(prefix) else { continue };
                let pid: Option<u32> = rest.split('-').next().and_then(|p| p.parse().ok());
                if pid.is_some_and(|pid| !process_is_running(pid))
                    && entry.path().is_dir()
                    && std::fs::remove_dir_all(entry.path()).is_ok()
                {
                    log(&format!(
                        "removed {}, left by an interrupted bake (process {})",
                        entry.path().display(),
                        pid.unwrap_or(0)
                    ));
                }
            }
        }
    }
}

/// Whether a process with this id runs (Linux: `/proc`; elsewhere assumed, so
/// nothing of a running bake is removed).
fn process_is_running(pid: u32) -> bool {
    if pid == std::process::id() {
        return false;
    }
    if Path::new("/proc/self").exists() {
        return Path::new(&format!("/proc/{pid}")).exists();
    }
    true
}

/// Every file below `root`, relative and `/`-separated, without the hidden
/// working folders of bakes. Links are listed, not followed.
fn list_files(root: &Path) -> Result<BTreeSet<String>> {
    let mut out = BTreeSet::new();
    let mut stack = vec![PathBuf::new()];
    while let Some(rel) = stack.pop() {
        let dir = root.join(&rel);
        let entries = std::fs::read_dir(&dir).with_context(|| format!("cannot list {}", dir.display()))?;
        for entry in entries {
            let entry = entry.with_context(|| format!("cannot list {}", dir.display()))?;
            let name = entry.file_name().to_string_lossy().into_owned();
            if rel.as_os_str().is_empty() && name.starts_with(TMP_PREFIX) {
                continue;
            }
            let child = rel.join(&name);
            if entry.file_type().is_ok_and(|t| t.is_dir()) {
                stack.push(child);
            } else {
                out.insert(child.to_string_lossy().replace('\\', "/"));
            }
        }
    }
    Ok(out)
}
