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
//! Only names of the bake's own layout count as its files ([`is_bake_file`]),
//! whatever the list says, and no path through a symbolic link inside the
//! folder is written or removed: a doctored list or a planted link cannot make a
//! bake remove a user's file.
//!
//! The new scene is written into a hidden folder inside `--out`
//! (`.sylva-tmp-PID`) and moved into place at the end, `scene.json` last: a
//! reader never sees a half-written scene as complete, and a failed bake leaves
//! the old scene as it was (every destination is checked before the first
//! move). Leftovers of an interrupted bake (Ctrl-C, kill -9) are removed by the
//! next bake into the same folder, on Linux, where `/proc` tells whether the
//! process that made them still runs.

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
    /// Where the scene goes: the real, canonical folder (the target of `--out`
    /// when it is a link).
    real: PathBuf,
    /// As the user named it, for messages.
    named: PathBuf,
    /// Whether files the bake did not write may stay beside the scene.
    force: bool,
    /// Whether this run created the folder (removed again, if still empty,
    /// when the bake fails or stops before writing).
    created: bool,
    /// The inputs, canonical: never removed, whatever a list says.
    inputs: Vec<PathBuf>,
}

impl Drop for OutDir {
    fn drop(&mut self) {
        if self.created {
            // Only an empty folder goes: one that a finished bake filled stays.
            let _ = std::fs::remove_dir(&self.real);
        }
    }
}

/// What a folder holds: the files of an earlier bake, and the others.
struct Survey {
    owned: BTreeSet<String>,
    foreign: Vec<String>,
}

/// Whether `rel` is a name of the bake's own layout: `scene.json`,
/// `species/*.pack`, `tiles/*.tile`, `tiles/*.ids`, `tiles/*.attr`, `index/*.json`,
/// `canopy/<level>/*.cnpy`, the terrain's (docs/FORMAT.md). A new kind of scene file must be added here.
#[must_use]
pub fn is_bake_file(rel: &str) -> bool {
    let plain = |f: &str, ext: &[&str]| !f.starts_with('.') && ext.iter().any(|e| f.len() > e.len() && f.ends_with(e));
    match rel.split('/').collect::<Vec<_>>().as_slice() {
        ["scene.json"] => true,
        ["species", f] => plain(f, &[".pack"]),
        ["tiles", f] => plain(f, &[".tile", ".ids", ".attr"]),
        ["index", f] => plain(f, &[".json"]),
        ["canopy", level, f] => level.parse::<u8>().is_ok() && plain(f, &[".cnpy"]),
        ["terrain", level, f] => level.parse::<u8>().is_ok() && plain(f, &[".terr"]),
        ["terrain", "img", level, f] => level.parse::<u8>().is_ok() && plain(f, &[".jpg"]),
        _ => false,
    }
}

impl OutDir {
    /// Checks `out` before any long work: it is a folder or can be one; it
    /// holds no input and no file a bake did not write (unless `force`).
    /// Leftovers of interrupted bakes in it are then removed.
    ///
    /// # Errors
    /// Every refusal names the folder and the files, and says what to do.
    pub fn prepare(out: &Path, inputs: &[&Path], force: bool, log: &dyn Fn(&str)) -> Result<OutDir> {
        let is_link = std::fs::symlink_metadata(out).is_ok_and(|m| m.file_type().is_symlink());
        if is_link && std::fs::metadata(out).is_err() {
            bail!("--out {} is a symbolic link to a folder that does not exist", out.display());
        }
        let created = match std::fs::metadata(out) {
            Ok(m) if m.is_dir() => false,
            Ok(_) => bail!("--out {} exists and is not a folder", out.display()),
            Err(_) => {
                std::fs::create_dir_all(out).with_context(|| format!("cannot create --out {}", out.display()))?;
                true
            }
        };
        let real = std::fs::canonicalize(out).with_context(|| format!("cannot resolve --out {}", out.display()))?;
        if is_link {
            log(&format!("--out {} is a link: writing the scene into {}", out.display(), real.display()));
        }
        let inputs: Vec<PathBuf> = inputs.iter().filter_map(|i| std::fs::canonicalize(i).ok()).collect();
        let dir = OutDir { real, named: out.to_path_buf(), force, created, inputs };
        if let Some(input) = dir.inputs.iter().find(|i| i.starts_with(&dir.real)) {
            if !force {
                bail!(
                    "--out {} holds the input {}: a bake never writes over its inputs; bake into another folder, or \
                     pass --force to write the scene beside them (they are kept)",
                    dir.named.display(),
                    input.display()
                );
            }
        }
        let survey = dir.survey()?;
        dir.check_foreign(&survey.foreign)?;
        dir.remove_leftovers(log);
        if !survey.owned.is_empty() {
            let shown: Vec<&str> = survey.owned.iter().take(4).map(String::as_str).collect();
            log(&format!(
                "replacing the scene in {}: its earlier bake's {} files ({}{}) are replaced or removed{}",
                dir.named.display(),
                survey.owned.len(),
                shown.join(", "),
                if survey.owned.len() > shown.len() { ", …" } else { "" },
                if survey.foreign.is_empty() {
                    String::new()
                } else {
                    format!("; {} other files are kept (--force)", survey.foreign.len())
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
        if std::fs::symlink_metadata(&tmp).is_ok() {
            std::fs::remove_dir_all(&tmp).with_context(|| format!("cannot remove {}", tmp.display()))?;
        }
        std::fs::create_dir(&tmp).with_context(|| format!("cannot write into --out {}", self.named.display()))?;
        let result = write(&tmp).and_then(|value| self.commit(&tmp).map(|()| value));
        let _ = std::fs::remove_dir_all(&tmp);
        result
    }

    /// Refuses files no bake wrote (without `--force`), and with `--force`
    /// those in the way of the scene's own names.
    fn check_foreign(&self, foreign: &[String]) -> Result<()> {
        if !foreign.is_empty() && !self.force {
            bail!("{}", self.foreign_message(foreign));
        }
        let in_the_way = |f: &&String| {
            f.as_str() == "scene.json"
                || ["species", "tiles", "index", "canopy"].contains(&f.as_str())
                || is_bake_file(f)
        };
        if let Some(taken) = foreign.iter().find(in_the_way) {
            bail!(
                "--out {} holds {taken}, which no bake wrote and a scene needs: it is kept; bake into another folder",
                self.named.display()
            );
        }
        Ok(())
    }

    fn commit(&self, tmp: &Path) -> Result<()> {
        // Checked again: a file may have appeared during a long bake.
        let survey = self.survey()?;
        self.check_foreign(&survey.foreign)?;
        let old = survey.owned;
        let new = list_files(tmp)?;
        if let Some(odd) = new.iter().find(|f| !is_bake_file(f)) {
            bail!(
                "internal error: the bake wrote {odd}, which is not a name of a scene's layout (out_dir::is_bake_file)"
            );
        }
        // Every destination is checked before anything changes, so a failure
        // leaves the old scene whole.
        for rel in &new {
            self.writable(rel)?;
        }
        // Record old and new first: a bake stopped half-way through the moves
        // still knows every file here that is its own.
        self.record(&old.union(&new).cloned().collect())?;
        let scene_json = "scene.json".to_string();
        let manifest = self.real.join(&scene_json);
        if std::fs::symlink_metadata(&manifest).is_ok() {
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
            // Only a regular file of ours, reached without a link, never an input.
            let regular = std::fs::symlink_metadata(&path).is_ok_and(|m| m.file_type().is_file());
            if !regular || self.through_link(rel) || self.inputs.contains(&path) {
                continue;
            }
            std::fs::remove_file(&path).with_context(|| format!("cannot remove the old {}", path.display()))?;
            for d in Path::new(rel).ancestors().skip(1).filter(|d| !d.as_os_str().is_empty()) {
                dirs.insert(d.to_path_buf());
            }
        }
        // Folders the old scene used and the new one does not, if now empty
        // (deepest first: terrain/3 before terrain).
        for d in dirs.iter().rev() {
            let _ = std::fs::remove_dir(self.real.join(d));
        }
        self.record(&new)
    }

    /// Whether `rel` can be written: its folders inside the output are real
    /// folders (or absent), and the name is free or a file of the bake's.
    fn writable(&self, rel: &str) -> Result<()> {
        if self.through_link(rel) {
            bail!("cannot write {rel} into --out {}: a folder on its way is no real folder", self.named.display());
        }
        if std::fs::symlink_metadata(self.real.join(rel)).is_ok_and(|m| m.is_dir()) {
            bail!("cannot write {rel} into --out {}: a folder has that name", self.named.display());
        }
        Ok(())
    }

    /// Whether a folder on the way to `rel` (inside the output) exists and is
    /// not a real folder (a link, or a file).
    fn through_link(&self, rel: &str) -> bool {
        let mut at = self.real.clone();
        let parts: Vec<&str> = rel.split('/').collect();
        parts[..parts.len().saturating_sub(1)].iter().any(|part| {
            at.push(part);
            std::fs::symlink_metadata(&at).is_ok_and(|m| !m.file_type().is_dir())
        })
    }

    /// Writes the list of the bake's files (to a temporary file, then renamed:
    /// never half-written, and a link in its place is replaced, not followed).
    fn record(&self, files: &BTreeSet<String>) -> Result<()> {
        let list = OwnedList { format: "sylva-bake-files".into(), version: 1, files: files.iter().cloned().collect() };
        let path = self.real.join(OWNED_LIST);
        let tmp = self.real.join(format!("{TMP_PREFIX}{}-list", std::process::id()));
        let mut bytes = serde_json::to_vec_pretty(&list)?;
        bytes.push(b'\n');
        std::fs::write(&tmp, bytes)
            .and_then(|()| std::fs::rename(&tmp, &path))
            .with_context(|| format!("cannot write {}", path.display()))
    }

    /// The files an earlier bake wrote here (its list, or for a scene baked
    /// before lists existed, a valid `scene.json` and the files of the
    /// layout), and the files no bake wrote. One walk of the folder.
    fn survey(&self) -> Result<Survey> {
        let all = list_files(&self.real)?;
        let list_path = self.real.join(OWNED_LIST);
        let listed: Option<BTreeSet<String>> = if std::fs::symlink_metadata(&list_path)
            .is_ok_and(|m| m.file_type().is_file())
        {
            let bytes = std::fs::read(&list_path).with_context(|| format!("cannot read {}", list_path.display()))?;
            let list: OwnedList = serde_json::from_slice(&bytes)
                .with_context(|| format!("{} is not a list of baked files", list_path.display()))?;
            Some(list.files.into_iter().collect())
        } else {
            None
        };
        let legacy = listed.is_none()
            && std::fs::read(self.real.join("scene.json"))
                .ok()
                .is_some_and(|b| sylva::format::Manifest::decode("scene.json", &b).is_ok());
        let owned: BTreeSet<String> = all
            .iter()
            .filter(|f| is_bake_file(f) && listed.as_ref().map_or(legacy, |l| l.contains(*f)))
            .cloned()
            .collect();
        let foreign = all.into_iter().filter(|f| !owned.contains(f) && f != OWNED_LIST).collect();
        Ok(Survey { owned, foreign })
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
    /// (`.sylva-tmp-PID`, `.sylva-tmp-PID-buckets`) and beside the folder
    /// (`.NAME.tmp-PID`, `.NAME.buckets-PID`, the layout of earlier versions).
    /// Names must match exactly: `.scene.tmp-2023-backup` is not ours.
    fn remove_leftovers(&self, log: &dyn Fn(&str)) {
        let name = self.real.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
        let parent = self.real.parent().unwrap_or(Path::new("/"));
        let here = |f: &str| {
            let rest = f.strip_prefix(TMP_PREFIX)?;
            let pid = rest.strip_suffix("-buckets").unwrap_or(rest);
            pid_of(pid)
        };
        let beside = |f: &str| {
            let rest = f.strip_prefix(&format!(".{name}."))?;
            pid_of(rest.strip_prefix("tmp-").or_else(|| rest.strip_prefix("buckets-"))?)
        };
        for (dir, matches) in [(self.real.as_path(), &here as &dyn Fn(&str) -> Option<u32>), (parent, &beside)] {
            let Ok(entries) = std::fs::read_dir(dir) else { continue };
            for entry in entries.flatten() {
                let file_name = entry.file_name().to_string_lossy().into_owned();
                let Some(pid) = matches(&file_name) else { continue };
                let is_dir = std::fs::symlink_metadata(entry.path()).is_ok_and(|m| m.file_type().is_dir());
                if is_dir && !process_is_running(pid) && std::fs::remove_dir_all(entry.path()).is_ok() {
                    log(&format!("removed {}, left by an interrupted bake (process {pid})", entry.path().display()));
                }
            }
        }
    }
}

/// A process id written as digits only.
fn pid_of(text: &str) -> Option<u32> {
    (!text.is_empty() && text.bytes().all(|b| b.is_ascii_digit())).then(|| text.parse().ok()).flatten()
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
/// working folders of bakes. Links are listed as files, never followed.
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

/// Writes a file; the error names it (a full disk, a read-only folder).
pub fn write_file(path: &Path, bytes: &[u8]) -> Result<()> {
    std::fs::write(path, bytes).with_context(|| format!("cannot write {}", path.display()))
}

/// Creates a folder and its parents; the error names it.
pub fn create_dir(path: &Path) -> Result<()> {
    std::fs::create_dir_all(path).with_context(|| format!("cannot create {}", path.display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_names_of_the_layout_are_bake_files() {
        for ok in [
            "scene.json",
            "species/oak.pack",
            "tiles/-1_2.tile",
            "tiles/0_0.ids",
            "index/r0.json",
            "canopy/3/5_7.cnpy",
            "terrain/3/5_7.terr",
            "terrain/img/2/1_3.jpg",
        ] {
            assert!(is_bake_file(ok), "{ok}");
        }
        for not in [
            "thesis.txt",
            "trees.csv",
            "tiles/notes.txt",
            "species/.pack",
            "species/.hidden.pack",
            "index/r.json/x",
            "canopy/r0.cnpy",
            "canopy/x/1_2.cnpy",
            "canopy/2/.cnpy",
            "../scene.json",
            "lnk/important.doc",
            "species/../thesis.txt",
            "tiles",
            "terrain/img/x/1_3.jpg",
            "terrain/img/2/photo.png",
        ] {
            assert!(!is_bake_file(not), "{not}");
        }
        assert_eq!(pid_of("123"), Some(123));
        for not in ["", "2023-backup", "12a", "-1"] {
            assert_eq!(pid_of(not), None, "{not}");
        }
    }
}
