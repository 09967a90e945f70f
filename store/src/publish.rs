//! Publishing a run's outputs into DIR as one set: DIR never holds files of two runs at once,
//! and a set is complete exactly when its `marker` (e.g. `summary.json`) exists.
//!
//! Order, each step durable before the next (see [`Store::publish`]):
//! 1. the plan — new files, old outputs to remove, output directories — is written to
//!    `.talus/publishing` atomically (the journal [`Store::recover`] finishes or undoes);
//! 2. the old marker goes first, then every other old talus output (also those the new set has
//!    again: a file is never replaced in place, so no reader mixes two versions);
//! 3. each new file is hard-linked (or, across devices, copied) under a unique temporary name in
//!    `.talus/tmp` and renamed into place, the marker last;
//! 4. empty output directories the new set does not use are removed, DIR is fsynced and the
//!    journal removed.
//!
//! DIR belongs to the user: only entries the caller's `ours` accepts are ever removed, an entry
//! of the new set that exists and is not ours is an error before anything is touched, and a
//! directory goes only when it is empty.

use std::collections::BTreeSet;
use std::fs;
use std::io;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use talus_base::{Error, Result};

use super::fsops::{
    no_links, out_err, parent, remove_any, replace_file, sync_dir, sync_file, tmp_name,
};
use super::unit_ref::{check_rel_path, UnitRef};
use super::Store;

/// The journal of a publish in progress (`.talus/publishing`). It is read back by whichever
/// command finds it, possibly from a folder someone else wrote: [`Journal::check`] holds every
/// path in it to DIR before anything is done.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub(super) struct Journal {
    /// The new set: source file (relative to `.talus/units`: `<kind>/<name>/<file>`) and name
    /// in DIR, the marker last.
    pub files: Vec<(PathBuf, String)>,
    pub marker: String,
    /// Old talus outputs to remove, the marker (if there was one) first.
    pub remove: Vec<String>,
    /// Output directories the store may remove when empty: existing ones `ours` accepted, and
    /// those step 3 creates. Deepest first.
    pub dirs: Vec<String>,
}

impl Store {
    pub(super) fn journal_path(&self) -> PathBuf {
        self.work.join("publishing")
    }

    /// Publish `files` (finished unit files, each with its name in DIR, `/`-separated) as DIR's
    /// outputs, `marker` (one of the names) last. `ours(name)` tells a talus output from the
    /// user's files: it is asked about every top-level entry of DIR (but `.talus`), and about
    /// the entries of a directory only when it accepted that directory or the new set puts
    /// files in it. Run it under the run lock. On an error, DIR is left without outputs (or, if
    /// even that fails, with the journal for [`Store::recover`]).
    pub fn publish(
        &self,
        files: &[(PathBuf, String)],
        marker: &str,
        ours: &dyn Fn(&str) -> bool,
    ) -> Result<()> {
        let journal = self.plan(files, marker, ours)?;
        let bytes = serde_json::to_vec_pretty(&journal)
            .map_err(|e| Error::Internal(format!("publish journal: {e}")))?;
        replace_file(&self.tmp(), &self.journal_path(), &bytes)?;
        self.apply(&journal).inspect_err(|_| {
            #[cfg(test)]
            if fault::crashed() {
                return;
            }
            // The old set may be gone already and the new one is partial: fall back to none.
            let _ = self.undo(&journal);
        })
    }

    /// Check the new set and list what is to be removed, touching nothing.
    fn plan(
        &self,
        files: &[(PathBuf, String)],
        marker: &str,
        ours: &dyn Fn(&str) -> bool,
    ) -> Result<Journal> {
        let mut names = BTreeSet::new();
        let mut new_dirs = BTreeSet::new();
        for (src, name) in files {
            check_rel_path("output", name)?;
            if is_work_area(name) {
                return Err(Error::Internal(format!("output {name:?} inside .talus")));
            }
            if !names.insert(name.as_str()) {
                return Err(Error::Internal(format!("output {name:?} listed twice")));
            }
            let m = fs::metadata(src).map_err(out_err(src))?;
            if !m.is_file() {
                return Err(Error::output(
                    src,
                    io::Error::other(format!("source of output {name} is not a file")),
                ));
            }
            let mut a = Path::new(name.as_str()).parent();
            while let Some(d) = a.filter(|d| !d.as_os_str().is_empty()) {
                new_dirs.insert(d.to_string_lossy().into_owned());
                a = d.parent();
            }
        }
        if !names.contains(marker) {
            return Err(Error::Internal(format!(
                "marker {marker:?} is not among the outputs"
            )));
        }
        let mut remove = Vec::new();
        let mut dirs = Vec::new();
        self.scan("", ours, &new_dirs, &mut remove, &mut dirs)?;
        // Conflicts with the user's files, before anything changes.
        for name in names
            .iter()
            .copied()
            .chain(new_dirs.iter().map(String::as_str))
        {
            let path = self.dir.join(name);
            let is_dir_needed = new_dirs.contains(name);
            match fs::symlink_metadata(&path) {
                Err(_) => {
                    if is_dir_needed && !dirs.iter().any(|d| d == name) {
                        dirs.push(name.to_string());
                    }
                }
                Ok(m) if is_dir_needed && m.is_dir() => {}
                Ok(_) if remove.iter().any(|r| r == name) => {}
                Ok(_) => {
                    return Err(Error::output(
                        &path,
                        io::Error::new(
                            io::ErrorKind::AlreadyExists,
                            "exists and is not a talus output; not replacing it",
                        ),
                    ))
                }
            }
        }
        remove.sort();
        if let Some(i) = remove.iter().position(|r| r == marker) {
            let m = remove.remove(i);
            remove.insert(0, m);
        }
        // Deepest first, so a parent is tried after its children.
        dirs.sort_by(|a, b| {
            b.matches('/')
                .count()
                .cmp(&a.matches('/').count())
                .then(a.cmp(b))
        });
        let units = self.units();
        let relative = |(src, name): &(PathBuf, String)| -> Result<(PathBuf, String)> {
            let rel = src.strip_prefix(&units).map_err(|_| {
                Error::Internal(format!(
                    "output {name}: its source {} is not a unit's file",
                    src.display()
                ))
            })?;
            Ok((rel.to_path_buf(), name.clone()))
        };
        let mut ordered: Vec<(PathBuf, String)> = files
            .iter()
            .filter(|(_, n)| n != marker)
            .map(relative)
            .collect::<Result<_>>()?;
        for f in files.iter().filter(|(_, n)| n == marker) {
            ordered.push(relative(f)?);
        }
        Ok(Journal {
            files: ordered,
            marker: marker.to_string(),
            remove,
            dirs,
        })
    }

    /// Collect the old outputs below DIR/`rel` (see [`Store::publish`] for where `ours` is asked).
    fn scan(
        &self,
        rel: &str,
        ours: &dyn Fn(&str) -> bool,
        new_dirs: &BTreeSet<String>,
        remove: &mut Vec<String>,
        dirs: &mut Vec<String>,
    ) -> Result<()> {
        let here = self.dir.join(rel);
        for entry in super::fsops::sorted_names(&here)? {
            if rel.is_empty() && entry == ".talus" {
                continue;
            }
            let name = if rel.is_empty() {
                entry.clone()
            } else {
                format!("{rel}/{entry}")
            };
            let path = here.join(&entry);
            let meta = fs::symlink_metadata(&path).map_err(out_err(&path))?;
            if meta.is_dir() {
                let accepted = ours(&name);
                if accepted {
                    dirs.push(name.clone());
                }
                if accepted || new_dirs.contains(&name) {
                    self.scan(&name, ours, new_dirs, remove, dirs)?;
                }
            } else if ours(&name) {
                remove.push(name);
            }
        }
        Ok(())
    }

    /// Steps 2 to 4 (also the roll-forward of [`Store::recover`]: every step may be redone).
    pub(super) fn apply(&self, j: &Journal) -> Result<()> {
        let mut touched = BTreeSet::new();
        self.remove_outputs(j, &mut touched)?;
        let needed: BTreeSet<&str> = j.files.iter().flat_map(|(_, n)| ancestors(n)).collect();
        for d in j.dirs.iter().filter(|d| !needed.contains(d.as_str())) {
            let path = self.out_path(d)?;
            // Fails, as it should, on a directory that still holds anything.
            if fs::remove_dir(&path).is_ok() {
                touched.insert(parent(&path).to_path_buf());
            }
        }
        for (i, (src, name)) in j.files.iter().enumerate() {
            let dest = self.out_path(name)?;
            if *name == j.marker {
                // Everything else of the set is durable before the marker says it is complete.
                sync_dirs(&touched)?;
            }
            #[cfg(test)]
            fault::check(i, &dest)?;
            let _ = i;
            self.place(&self.units().join(src), &dest)?;
            touched.insert(parent(&dest).to_path_buf());
        }
        touched.insert(self.dir.clone());
        sync_dirs(&touched)?;
        remove_any(&self.journal_path())?;
        sync_dir(&self.work)
    }

    /// Step 2: the marker first (durably), then every other old output.
    fn remove_outputs(&self, j: &Journal, touched: &mut BTreeSet<PathBuf>) -> Result<()> {
        for (i, name) in j.remove.iter().enumerate() {
            let path = self.out_path(name)?;
            remove_any(&path)?;
            remove_any(&side_tmp(&path))?;
            touched.insert(parent(&path).to_path_buf());
            if i == 0 && *name == j.marker {
                sync_dir(parent(&path))?;
            }
        }
        Ok(())
    }

    /// Put `src` at `dest` atomically: a hard link (or copy) under a unique name in `tmp/`,
    /// renamed into place. A link costs nothing (a copy of a 120M-point pair's outputs is 4.2 GB
    /// and took 65 s here); a published file edited in place is then an edit of the unit's file
    /// too, which the executor notices before reusing the unit ([`Store::edited_files`]) and
    /// recomputes. When `dest`'s directory is on another device than the store, the copy is made
    /// beside `dest` instead, under a fixed hidden name a retry overwrites.
    fn place(&self, src: &Path, dest: &Path) -> Result<()> {
        let dir = parent(dest);
        fs::create_dir_all(dir).map_err(out_err(dir))?;
        let t = tmp_name(&self.tmp(), "publish");
        if fs::hard_link(src, &t).is_err() {
            fs::copy(src, &t).map_err(out_err(&t))?;
            sync_file(&t)?;
        }
        match fs::rename(&t, dest) {
            Ok(()) => Ok(()),
            Err(e) if e.kind() == io::ErrorKind::CrossesDevices => {
                let _ = fs::remove_file(&t);
                let side = side_tmp(dest);
                fs::copy(src, &side).map_err(out_err(&side))?;
                sync_file(&side)?;
                fs::rename(&side, dest).map_err(out_err(dest))
            }
            Err(e) => {
                let _ = fs::remove_file(&t);
                Err(Error::output(dest, e))
            }
        }
    }

    /// Back to "no outputs": the marker first, then every file of either set, then the store's
    /// empty directories; the journal goes last.
    pub(super) fn undo(&self, j: &Journal) -> Result<()> {
        let marker = self.out_path(&j.marker)?;
        remove_any(&marker)?;
        sync_dir(parent(&marker))?;
        let mut touched = BTreeSet::new();
        let names = j.files.iter().map(|(_, n)| n).chain(j.remove.iter());
        for name in names {
            let path = self.out_path(name)?;
            remove_any(&path)?;
            remove_any(&side_tmp(&path))?;
            touched.insert(parent(&path).to_path_buf());
        }
        for d in &j.dirs {
            let path = self.out_path(d)?;
            if fs::remove_dir(&path).is_ok() {
                touched.insert(parent(&path).to_path_buf());
            }
        }
        touched.insert(self.dir.clone());
        sync_dirs(&touched)?;
        remove_any(&self.journal_path())?;
        sync_dir(&self.work)
    }
}

impl Store {
    /// DIR/`name` for an output name already checked ([`check_rel_path`]), its folders inside
    /// DIR walked without following a link: a folder of DIR replaced by a link (`pairs` → `/`)
    /// must not make a removal or a placement land outside DIR.
    fn out_path(&self, name: &str) -> Result<PathBuf> {
        let rel = Path::new(name);
        no_links(&self.dir, rel.parent().unwrap_or(Path::new("")))?;
        Ok(self.dir.join(rel))
    }
}

impl Journal {
    /// Hold every path of a journal read back from DIR to DIR (see [`Journal`]): each source a
    /// regular file of a finished unit (`<kind>/<name>/<file>` below `.talus/units`, no link on
    /// the way; an absolute path is taken only when it lies there, as journals before sources
    /// were relative wrote them), each name in DIR an output `ours` accepts (so a removal never
    /// reaches a file of the user's), nothing in `.talus`. The problem, or the journal with
    /// relative sources.
    pub(super) fn check(
        mut self,
        dir: &Path,
        units: &Path,
        ours: &dyn Fn(&str) -> bool,
    ) -> std::result::Result<Journal, String> {
        // Inside DIR: a relative name, not in `.talus`, no link among its folders.
        let inside = |what: &str, name: &str| -> std::result::Result<(), String> {
            if check_rel_path(what, name).is_err() || is_work_area(name) {
                return Err(format!("{what} {} is not a name inside DIR", shown(name)));
            }
            let folders = Path::new(name).parent().unwrap_or(Path::new(""));
            no_links(dir, folders).map_err(|e| e.to_string())
        };
        let name_ok = |what: &str, name: &str| -> std::result::Result<(), String> {
            inside(what, name)?;
            if !ours(name) {
                return Err(format!("{what} {} is not a talus output", shown(name)));
            }
            Ok(())
        };
        for (src, name) in &mut self.files {
            name_ok("the output", name)?;
            let rel = if src.is_absolute() || src.starts_with(units) {
                src.strip_prefix(units).map_err(|_| {
                    format!(
                        "the source {} of {name} lies outside DIR's store",
                        src.display()
                    )
                })?
            } else {
                src.as_path()
            };
            let text = rel.to_str().unwrap_or("");
            let mut parts = text.splitn(3, '/');
            let (kind, unit, file) = (parts.next(), parts.next(), parts.next());
            let ok = match (kind, unit, file) {
                (Some(k), Some(u), Some(f)) => {
                    UnitRef::new(k, u).is_ok() && check_rel_path("file", f).is_ok()
                }
                _ => false,
            };
            if !ok {
                return Err(format!(
                    "the source {} of {} is not a file of a unit in DIR's store",
                    shown(&src.to_string_lossy()),
                    shown(name)
                ));
            }
            *src = PathBuf::from(text);
            no_links(units, src).map_err(|e| e.to_string())?;
            if let Ok(m) = fs::symlink_metadata(units.join(&*src)) {
                if !m.is_file() {
                    return Err(format!(
                        "the source {} of {} is not a regular file",
                        src.display(),
                        shown(name)
                    ));
                }
            }
        }
        if !self.files.iter().any(|(_, n)| *n == self.marker) {
            return Err(format!(
                "its marker {} is not among its outputs",
                shown(&self.marker)
            ));
        }
        for name in &self.remove {
            name_ok("the old output", name)?;
        }
        for d in &self.dirs {
            // Only ever removed when empty, but never outside DIR or in .talus.
            inside("the folder", d)?;
        }
        Ok(self)
    }
}

/// `s` quoted for a message, cut at 80 characters (a crafted name may be megabytes long).
fn shown(s: &str) -> String {
    if s.chars().count() > 80 {
        format!("{:?}…", s.chars().take(80).collect::<String>())
    } else {
        format!("{s:?}")
    }
}

/// `.talus` or a name below it: the store, never an output.
fn is_work_area(name: &str) -> bool {
    name.split('/').next() == Some(".talus")
}

/// fsync every directory of `dirs` that still exists (one emptied and removed has nothing left
/// to make durable but its removal, which its parent's fsync covers).
fn sync_dirs(dirs: &BTreeSet<PathBuf>) -> Result<()> {
    dirs.iter()
        .filter(|d| d.is_dir())
        .try_for_each(|d| sync_dir(d))
}

/// The hidden temporary beside `dest` used for a copy across devices.
fn side_tmp(dest: &Path) -> PathBuf {
    let base = dest
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    dest.with_file_name(format!(".{base}.talus-tmp"))
}

/// `a`, `a/b` for `a/b/c`.
fn ancestors(name: &str) -> impl Iterator<Item = &str> {
    name.match_indices('/').map(move |(i, _)| &name[..i])
}

/// Test-only fault injection into step 3: fail (an ordinary error, which publish undoes) or
/// "crash" (return at once, as a SIGKILL would leave things) before placing file number `at`.
#[cfg(test)]
pub(crate) mod fault {
    use std::cell::Cell;

    #[derive(Clone, Copy, Debug, PartialEq, Eq)]
    pub(crate) enum Fault {
        Fail,
        Crash,
    }

    thread_local! {
        static AT: Cell<Option<(usize, Fault)>> = const { Cell::new(None) };
        static CRASHED: Cell<bool> = const { Cell::new(false) };
    }

    /// Arm a fault for the next publish on this thread.
    pub(crate) fn arm(at: usize, fault: Fault) {
        AT.with(|a| a.set(Some((at, fault))));
        CRASHED.with(|c| c.set(false));
    }

    pub(super) fn check(i: usize, dest: &std::path::Path) -> talus_base::Result<()> {
        match AT.with(|a| a.get()) {
            Some((at, fault)) if at == i => {
                AT.with(|a| a.set(None));
                CRASHED.with(|c| c.set(fault == Fault::Crash));
                Err(talus_base::Error::output(
                    dest,
                    std::io::Error::other(format!("injected {fault:?}")),
                ))
            }
            _ => Ok(()),
        }
    }

    pub(super) fn crashed() -> bool {
        CRASHED.with(|c| c.get())
    }
}
