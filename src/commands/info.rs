//! `talus info`: what talus sees in a point cloud and the parameters it would derive for it.

use std::path::{Path, PathBuf};

use serde::Serialize;

use crate::error::Result;
use crate::io::classes::Classes;
use crate::io::{self, Bounds, CloudFormat};
use crate::params::{Params, UserParams};
use crate::sampling::{self, Spacing};

/// The report for one file.
#[derive(Debug, Serialize)]
pub(crate) struct CloudReport {
    pub(crate) path: PathBuf,
    pub(crate) format: CloudFormat,
    pub(crate) format_detail: String,
    pub(crate) points: u64,
    pub(crate) bounds: Bounds,
    pub(crate) crs: String,
    pub(crate) crs_wkt: Option<String>,
    /// The points per LAS class, and those a comparison leaves out by default (null for text
    /// and PLY).
    pub(crate) classes: Option<crate::units::outputs::SurveyClasses>,
    /// None when it cannot be measured: `spacing_note` says why.
    pub(crate) spacing: Option<Spacing>,
    /// Why there is no spacing (the classes a comparison keeps leave no point, too few distinct
    /// positions, coordinates so large that distances overflow); the file is described all the
    /// same, and a comparison with it as BEFORE would be refused so.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub(crate) spacing_note: Option<String>,
    /// None without a spacing.
    pub(crate) derived: Option<Params>,
}

/// Inspect one cloud (reads it once or twice; never holds more than a window of it). The spacing
/// is measured, as a comparison measures it, on the classes a comparison keeps by default; the
/// classes are counted in the same pass.
pub(crate) fn inspect(path: &Path) -> Result<CloudReport> {
    let reader = io::open(path)?;
    let info = reader.info().clone();
    drop(reader);
    let (spacing, classes, note) = match sampling::measure_or_why(path, Some(&Classes::default()))?
    {
        Ok(m) => (Some(m.spacing), m.classes, None),
        Err(why) => (None, why.classes, Some(why.problem)),
    };
    let classes = classes.map(|c| crate::units::outputs::SurveyClasses::of(&c));
    let derived = spacing
        .as_ref()
        .map(|s| Params::resolve(&UserParams::default(), s.effective_spacing))
        .transpose()?;
    Ok(CloudReport {
        path: path.to_path_buf(),
        format: info.format,
        format_detail: info.format_detail,
        points: info.point_count,
        bounds: info.bounds,
        crs: info.crs.describe(),
        crs_wkt: info.crs.wkt,
        classes,
        spacing,
        spacing_note: note,
        derived,
    })
}

/// `println!` into a String.
macro_rules! outln {
    ($out:expr, $($arg:tt)*) => {{
        use std::fmt::Write as _;
        let _ = writeln!($out, $($arg)*);
    }};
}

/// Print reports for `files` to stdout, as text or JSON.
pub(crate) fn print(files: &[PathBuf], json: bool) -> Result<()> {
    let mut reports = Vec::new();
    for f in files {
        reports.push(inspect(f)?);
    }
    if json {
        let text = serde_json::to_string_pretty(&reports)
            .map_err(|e| crate::Error::Internal(e.to_string()))?;
        return write_stdout(&(text + "\n"));
    }
    let mut out = String::new();
    for r in &reports {
        let b = &r.bounds;
        outln!(out, "{}", r.path.display());
        outln!(out, "  format         {}", r.format_detail);
        outln!(out, "  points         {}", r.points);
        let show = crate::geom::show;
        outln!(
            out,
            "  bounds         x {} .. {}  y {} .. {}  z {} .. {}",
            show(b.min[0]),
            show(b.max[0]),
            show(b.min[1]),
            show(b.max[1]),
            show(b.min[2]),
            show(b.max[2])
        );
        outln!(out, "  crs            {}", r.crs);
        if let Some(c) = &r.classes {
            let per: Vec<String> = c
                .per_class
                .iter()
                .map(|k| format!("{}: {}", k.class, k.points))
                .collect();
            outln!(
                out,
                "  classes        {}{}",
                per.join(", "),
                if !c.classified {
                    " (unclassified: nothing is left out)".to_string()
                } else if c.left_out > 0 {
                    format!(
                        "; a comparison leaves out {} points (vegetation 3, 4, 5 and noise 7, 18; \
                         --classes chooses), and the spacing below is theirs without them",
                        c.left_out
                    )
                } else {
                    String::new()
                }
            );
        }
        let (Some(spacing), Some(p)) = (&r.spacing, &r.derived) else {
            outln!(
                out,
                "  spacing        not measurable: {}",
                r.spacing_note.as_deref().unwrap_or("")
            );
            outln!(
                out,
                "  parameters     none derived: a comparison refuses this file as BEFORE or AFTER \
                 for that reason"
            );
            continue;
        };
        outln!(
            out,
            "  spacing        {:.4} effective point spacing s = 1/√density: the parameters below derive from it",
            spacing.effective_spacing
        );
        outln!(
            out,
            "  density        {:.2} points per square unit of the CRS (per m² for metric input)",
            spacing.density
        );
        outln!(
            out,
            "  nearest point  {:.4} median distance from a point to its nearest neighbour ({}, {} points)",
            spacing.spacing,
            spacing.method,
            spacing.measured_points
        );
        outln!(
            out,
            "  parameters a comparison with this file as BEFORE would derive:"
        );
        for (flag, v, src) in [
            (
                "--core-spacing",
                p.core_spacing.value,
                &p.core_spacing.source,
            ),
            (
                "--normal-radius",
                p.normal_radius.value,
                &p.normal_radius.source,
            ),
            ("--cyl-radius", p.cyl_radius.value, &p.cyl_radius.source),
            ("--cyl-halflen", p.cyl_halflen.value, &p.cyl_halflen.source),
            (
                "--smooth-sigma",
                p.smooth_sigma.value,
                &p.smooth_sigma.source,
            ),
            ("--eps", p.eps.value, &p.eps.source),
        ] {
            outln!(out, "    {flag:<22} {v:<10.4} {src}");
        }
        outln!(
            out,
            "    {:<22} {:<10} {}",
            "--smooth-k",
            p.smooth_k.value,
            p.smooth_k.source
        );
        outln!(
            out,
            "    {:<22} {:<10} {}",
            "--cluster-min-points",
            p.cluster_min_points.value,
            p.cluster_min_points.source
        );
        outln!(
            out,
            "    {:<22} {:<10} measured by the comparison on the pair's stable ground: 3 σ_d + 1.96 × reg_error",
            "--threshold",
            "(pair)"
        );
        outln!(
            out,
            "    {:<22} {:<10} measured by the comparison on the pair's stable ground",
            "--reg-error",
            "(pair)"
        );
    }
    write_stdout(&out)
}

/// Write `text` to stdout. A reader that went away (`talus info | head`) is not an error and
/// not a panic, as `println!` would make it.
fn write_stdout(text: &str) -> Result<()> {
    use std::io::Write;
    let mut stdout = std::io::stdout().lock();
    match stdout
        .write_all(text.as_bytes())
        .and_then(|()| stdout.flush())
    {
        Err(e) if e.kind() != std::io::ErrorKind::BrokenPipe => {
            Err(crate::Error::output("stdout", e))
        }
        _ => Ok(()),
    }
}
