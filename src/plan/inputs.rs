//! What a survey argument names (SPEC.md §5): a point-cloud file, or a folder or glob of files
//! that together are one survey (surveys are delivered as tiles). A folder means every point
//! cloud in it (LAS, LAZ, text, PLY by extension; not recursive); a glob is a file pattern with
//! `*` and `?` in its last component (`flight_2019/*.laz`). Files are taken in name order, so a
//! survey's points stream in the same order on every run.

use std::path::{Path, PathBuf};

use crate::error::{Error, Result};
use crate::io::{self, Bounds, CloudInfo, Crs};

/// Extensions of the point-cloud files a folder is searched for.
const CLOUD_EXTENSIONS: &[&str] = &["las", "laz", "txt", "csv", "xyz", "pts", "ply"];

/// A point cloud of a survey folder by its extension: a file, or a FIFO or other special file
/// (not skipped in silence: reading it refuses it, naming it), never a folder.
fn is_cloud(p: &Path) -> bool {
    !p.is_dir()
        && p.extension().is_some_and(|e| {
            let e = e.to_string_lossy().to_ascii_lowercase();
            CLOUD_EXTENSIONS.contains(&e.as_str())
        })
}

/// Does `name` match the glob `pattern` (`*` any run, `?` any one character)?
pub(crate) fn glob_match(pattern: &str, name: &str) -> bool {
    let (p, n): (Vec<char>, Vec<char>) = (pattern.chars().collect(), name.chars().collect());
    // Classic two-pointer match with backtracking to the last `*`.
    let (mut i, mut j, mut star, mut mark) = (0, 0, None, 0);
    while j < n.len() {
        if i < p.len() && (p[i] == '?' || p[i] == n[j]) {
            i += 1;
            j += 1;
        } else if i < p.len() && p[i] == '*' {
            star = Some(i);
            mark = j;
            i += 1;
        } else if let Some(s) = star {
            i = s + 1;
            mark += 1;
            j = mark;
        } else {
            return false;
        }
    }
    while i < p.len() && p[i] == '*' {
        i += 1;
    }
    i == p.len()
}

/// The files a survey argument names, in name order.
pub(crate) fn survey_files(arg: &Path) -> Result<Vec<PathBuf>> {
    let text = arg.to_string_lossy();
    let name = arg.file_name().map(|n| n.to_string_lossy().into_owned());
    let pattern = name.filter(|n| n.contains('*') || n.contains('?'));
    let mut files: Vec<PathBuf> = if let Some(pat) = pattern {
        let dir = match arg.parent() {
            Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
            _ => PathBuf::from("."),
        };
        let rd = std::fs::read_dir(&dir)
            .map_err(|e| Error::input(arg, format!("cannot list {}: {e}", dir.display())))?;
        rd.filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| {
                !p.is_dir()
                    && p.file_name()
                        .is_some_and(|n| glob_match(&pat, &n.to_string_lossy()))
            })
            .collect()
    } else if arg.is_dir() {
        let rd = std::fs::read_dir(arg)
            .map_err(|e| Error::input(arg, format!("cannot list the folder: {e}")))?;
        rd.filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| is_cloud(p))
            .collect()
    } else if arg.exists() {
        vec![arg.to_path_buf()]
    } else {
        return Err(Error::input(arg, "no such file or folder"));
    };
    files.sort();
    if files.is_empty() {
        return Err(Error::input(
            arg,
            if text.contains('*') || text.contains('?') {
                "the pattern matches no file"
            } else {
                "the folder holds no point cloud (LAS, LAZ, text or PLY)"
            },
        ));
    }
    Ok(files)
}

/// A survey's files with what their headers say together.
#[derive(Debug, Clone)]
pub struct SurveyFiles {
    /// The argument as given (a file, folder or pattern).
    pub arg: PathBuf,
    pub infos: Vec<CloudInfo>,
}

/// Fewest points a survey may have: a normal needs a neighbourhood, a volume a triangle of each
/// epoch, and a handful of points can only give distances at the few core points they touch.
pub(crate) const MIN_SURVEY_POINTS: u64 = 10;

impl SurveyFiles {
    /// Open the headers of every file of `arg`; its tiles must share one CRS.
    pub(crate) fn open(arg: &Path) -> Result<SurveyFiles> {
        let files = survey_files(arg)?;
        let mut infos: Vec<CloudInfo> = Vec::with_capacity(files.len());
        for f in &files {
            let info = io::open(f)?.info().clone();
            if let Some(first) = infos.first() {
                if !same_crs(&first.crs, &info.crs) {
                    return Err(Error::input(
                        f,
                        format!(
                            "its CRS ({}) differs from {}'s ({}): the tiles of one survey must share one CRS",
                            info.crs.describe(),
                            first.path.display(),
                            first.crs.describe()
                        ),
                    ));
                }
            }
            infos.push(info);
        }
        let files = SurveyFiles {
            arg: arg.to_path_buf(),
            infos,
        };
        files.check_not_degenerate()?;
        Ok(files)
    }

    /// A survey of too few points, or whose points all lie on one vertical line (or coincide),
    /// describes no surface: refused as BEFORE and as AFTER alike, before anything runs (as
    /// AFTER it would otherwise give a few distances at the core points it happens to touch and
    /// a result with no stable ground).
    fn check_not_degenerate(&self) -> Result<()> {
        let n = self.points();
        if n < MIN_SURVEY_POINTS {
            return Err(Error::input(
                &self.arg,
                format!(
                    "holds {n} point(s): a survey needs at least {MIN_SURVEY_POINTS} to describe \
                     a surface"
                ),
            ));
        }
        let b = self.bounds();
        if b.max[0] - b.min[0] <= 0.0 && b.max[1] - b.min[1] <= 0.0 {
            return Err(Error::input(
                &self.arg,
                format!(
                    "all points coincide or lie on one vertical line (x {}, y {}): a survey \
                     must cover an area",
                    crate::geom::show(b.min[0]),
                    crate::geom::show(b.min[1])
                ),
            ));
        }
        Ok(())
    }

    /// Points of all files.
    pub(crate) fn points(&self) -> u64 {
        self.infos.iter().map(|i| i.point_count).sum()
    }

    /// The points of each file when every one is LAS or LAZ, whose headers count them exactly
    /// (`Survey::file_points`: what a tiling in parts ranges over); empty otherwise.
    pub(crate) fn las_points(&self) -> Vec<u64> {
        let las = |i: &CloudInfo| matches!(i.format, io::CloudFormat::Las | io::CloudFormat::Laz);
        match self.infos.iter().all(las) {
            true => self.infos.iter().map(|i| i.point_count).collect(),
            false => Vec::new(),
        }
    }

    /// Bounds of all files.
    pub(crate) fn bounds(&self) -> Bounds {
        let mut b = Bounds::empty();
        for i in &self.infos {
            b.grow(&i.bounds.min);
            b.grow(&i.bounds.max);
        }
        b
    }

    /// The first file's header (the CRS every file shares).
    pub(crate) fn first(&self) -> &CloudInfo {
        &self.infos[0]
    }

    /// The finest LAS scale of the files, per axis (None when no file has one).
    pub(crate) fn scale(&self) -> Option<[f64; 3]> {
        self.infos
            .iter()
            .filter_map(|i| i.scale)
            .reduce(|a, b| std::array::from_fn(|k| a[k].min(b[k])))
    }

    /// The format, e.g. `LAZ 1.4 point format 6` or `LAZ 1.4 point format 6 (12 files)`.
    pub(crate) fn format(&self) -> String {
        let f = &self.first().format_detail;
        match self.infos.len() {
            1 => f.clone(),
            n => format!("{f} ({n} files)"),
        }
    }
}

/// Do two CRSs name the same system? By EPSG code where both have one, else by their WKT (or
/// both having none).
fn same_crs(a: &Crs, b: &Crs) -> bool {
    match (a.epsg, b.epsg) {
        (Some(x), Some(y)) => x == y,
        _ => a.wkt == b.wkt && a.epsg == b.epsg,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn globs() {
        assert!(glob_match("*.laz", "a.laz"));
        assert!(glob_match("tile_??.laz", "tile_07.laz"));
        assert!(!glob_match("tile_??.laz", "tile_7.laz"));
        assert!(glob_match("*2019*", "flight_20190311_a.las"));
        assert!(!glob_match("*.laz", "a.las"));
        assert!(glob_match("*", ""));
    }
}
