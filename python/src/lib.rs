//! `talus._talus`: the native half of the Python package `talus` (python/talus/ is the other).
//!
//! - [`m3c2`]: M3C2 on numpy arrays. In memory when both epochs fit the memory budget (the same
//!   function a tile of `talus compare` calls, over the whole arrays as one tile, in the frame and
//!   with the parameters `talus compare` derives from the same points: the same numbers); else,
//!   and for `auto` orientation (its field is a unit of the pipeline), through the pipeline of
//!   `talus compare --m3c2-only` itself, with the arrays written as binary PLY (doubles: nothing
//!   rounded) into a scratch folder; its distances, spreads and normals are the in-memory ones
//!   rounded to f32, as the pipeline's results store them.
//! - [`compare`], [`campaign`]: the commands, on files.
//! - Interruption and progress for the Python side, which runs these calls in a thread and keeps
//!   the interpreter's main thread free for Ctrl-C.
//!
//! Every error is a `TalusError` (an `InputError`, also a `ValueError`, when it is the user's to
//! fix) carrying talus's message.

use std::path::{Path, PathBuf};
use std::sync::Mutex;

use numpy::{PyArray1, PyArrayMethods, PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::create_exception;
use pyo3::exceptions::{PyException, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use talus::commands::campaign::CampaignOptions;
use talus::commands::compare::{compare as run_compare, CompareOptions};
use talus::geom::{Bounds, Point3};
use talus::io::{CloudFormat, CloudInfo, Crs, PointReader};
use talus::m3c2::tile::{compute, EpochPoints, KeyedResult};
use talus::m3c2::{Extent, Orientation, Reach};
use talus::params::{Params, UserParams};
use talus::plan::layout::Layout;
use talus::plan::Plan;
use talus::store::Store;
use talus::units::m3c2::Merged;
use talus::Error;

create_exception!(
    talus,
    TalusError,
    PyException,
    "An error talus reports, with its message."
);
create_exception!(
    talus,
    InputError,
    TalusError,
    "Bad input or parameters (the command line's exit code 2)."
);

/// The Python exception of a talus error: `InputError` for the user's to fix, `TalusError` else
/// (an interruption is turned into `KeyboardInterrupt` by the Python side).
fn to_py(e: Error) -> PyErr {
    let code = e.exit_code();
    let text = e.to_string();
    let err = if code == 2 {
        InputError::new_err(text)
    } else {
        TalusError::new_err(text)
    };
    Python::attach(|py| {
        let _ = err.value(py).setattr("exit_code", code);
    });
    err
}

/// An N × 3 float64 C-contiguous array as points (the Python side converts and checks them).
fn points<'a>(name: &str, a: &'a PyReadonlyArray2<'_, f64>) -> PyResult<&'a [Point3]> {
    if a.shape()[1] != 3 {
        return Err(PyValueError::new_err(format!(
            "{name}: expected an N x 3 array, got {:?}",
            a.shape()
        )));
    }
    let flat = a
        .as_slice()
        .map_err(|_| PyValueError::new_err(format!("{name}: not a C-contiguous array")))?;
    let (pts, rest) = flat.as_chunks::<3>();
    debug_assert!(rest.is_empty());
    Ok(pts)
}

/// Points in memory as a talus point reader: what the spacing measurement reads a file with.
struct SliceReader<'a> {
    points: &'a [Point3],
    at: usize,
    info: CloudInfo,
}

impl<'a> SliceReader<'a> {
    fn new(name: &str, points: &'a [Point3], bounds: Bounds) -> Self {
        SliceReader {
            points,
            at: 0,
            info: CloudInfo {
                path: PathBuf::from(name),
                format: CloudFormat::Ply,
                format_detail: "numpy array".into(),
                point_count: points.len() as u64,
                bounds,
                crs: Crs::default(),
                scale: None,
                transform: None,
            },
        }
    }
}

impl PointReader for SliceReader<'_> {
    fn info(&self) -> &CloudInfo {
        &self.info
    }
    fn fill(&mut self, buf: &mut Vec<Point3>, max: usize) -> talus::Result<usize> {
        buf.clear();
        let end = (self.at + max).min(self.points.len());
        buf.extend_from_slice(&self.points[self.at..end]);
        self.at = end;
        Ok(buf.len())
    }
}

/// The M3C2 parameters of a `talus.m3c2` call.
struct M3c2Call {
    user: UserParams,
    registration_error: f64,
    out_of_core: Option<bool>,
    workdir: Option<PathBuf>,
}

/// One core point's outputs, as m3c2.laz gives them.
#[derive(Default)]
struct Columns {
    distance: Vec<f64>,
    lod: Vec<f64>,
    significant: Vec<bool>,
    spread1: Vec<f64>,
    spread2: Vec<f64>,
    count1: Vec<i64>,
    count2: Vec<i64>,
    normals: Vec<f64>,
    beyond_reach: Vec<bool>,
    sign_known: Vec<bool>,
}

impl Columns {
    /// Add a result with the registration error in its LoD95, as m3c2.laz writes it: beyond the
    /// user's half-length, no distance and no LoD.
    fn push(&mut self, k: &KeyedResult, reg_error: f64) {
        let r = k.r.with_registration(reg_error);
        let beyond = r.reach == Reach::Beyond;
        self.distance.push(r.measured());
        self.lod.push(if beyond { f64::NAN } else { r.uncertainty });
        self.significant.push(!beyond && r.significant);
        self.spread1.push(r.std_dev1);
        self.spread2.push(r.std_dev2);
        self.count1.push(r.count1 as i64);
        self.count2.push(r.count2 as i64);
        self.normals.extend_from_slice(&r.normal);
        self.beyond_reach.push(beyond);
        self.sign_known.push(r.sign_known);
    }

    fn into_dict<'py>(self, py: Python<'py>, route: &str) -> PyResult<Bound<'py, PyDict>> {
        let d = PyDict::new(py);
        let n = self.distance.len();
        d.set_item("distances", PyArray1::from_vec(py, self.distance))?;
        d.set_item("lodetection", PyArray1::from_vec(py, self.lod))?;
        d.set_item("significant", PyArray1::from_vec(py, self.significant))?;
        d.set_item("spread1", PyArray1::from_vec(py, self.spread1))?;
        d.set_item("spread2", PyArray1::from_vec(py, self.spread2))?;
        d.set_item("num_samples1", PyArray1::from_vec(py, self.count1))?;
        d.set_item("num_samples2", PyArray1::from_vec(py, self.count2))?;
        d.set_item(
            "normals",
            PyArray1::from_vec(py, self.normals).reshape([n, 3])?,
        )?;
        d.set_item("beyond_reach", PyArray1::from_vec(py, self.beyond_reach))?;
        d.set_item("sign_known", PyArray1::from_vec(py, self.sign_known))?;
        d.set_item("route", route)?;
        Ok(d)
    }
}

/// The effective spacing `talus compare` measures on a before survey of these points.
fn spacing_of(points: &[Point3], bounds: Bounds) -> talus::Result<f64> {
    let open = || -> talus::Result<Box<dyn PointReader + '_>> {
        Ok(Box::new(SliceReader::new("epoch1", points, bounds)))
    };
    let m = talus::sampling::measure_opened(Path::new("epoch1"), None, &open, &mut |_| {})?;
    Ok(m.spacing.effective_spacing)
}

/// M3C2 of `cores` between the two epochs, in memory or through the pipeline.
fn m3c2_points(
    before: &[Point3],
    after: &[Point3],
    cores: &[Point3],
    call: &M3c2Call,
) -> talus::Result<(Columns, &'static str)> {
    let bounds = [Bounds::of(before), Bounds::of(after), Bounds::of(cores)];
    // The inputs and the user's values, checked before anything is measured (as `compare`
    // checks them).
    if !bounds[0].overlaps_xy(&bounds[1]) {
        return Err(Error::Epochs(
            "epoch1 and epoch2: the epochs do not overlap".into(),
        ));
    }
    let budget = Params::resolve(&call.user, 1.0)?.memory_bytes.value;
    call.user.check_lengths_within(&bounds[..2])?;
    let auto = call
        .user
        .orientation
        .as_deref()
        .is_none_or(|o| o.parse::<Orientation>() == Ok(Orientation::Auto));
    let need = talus::units::m3c2::need((before.len() + after.len()) as u64);
    if call.out_of_core.unwrap_or(auto || need > budget) {
        return Ok((through_pipeline(before, after, cores, call)?, "pipeline"));
    }
    let spacing = match call.user.point_spacing {
        Some(s) => s,
        None => spacing_of(before, bounds[0])?,
    };
    let params = Params::resolve(&call.user, spacing)?;
    if auto {
        return Err(Error::Usage(
            "orientation 'auto' needs the survey's orientation field, a stage of the pipeline: \
             leave out_of_core unset or True, or give another orientation"
                .into(),
        ));
    }
    // The frame `compare` works in: the core-point anchor of its layout over the same inputs.
    let all = Bounds::union(&bounds);
    let side = (all.max[0] - all.min[0]).max(all.max[1] - all.min[1]);
    let layout = Layout::plan(&bounds, &all, 1.0, &params, Some(side.max(1.0)))?;
    let columns = |pts: &[Point3]| -> [Vec<f64>; 3] {
        std::array::from_fn(|k| pts.iter().map(|p| p[k]).collect())
    };
    let (b, a) = (columns(before), columns(after));
    let (ob, oa) = (vec![true; before.len()], vec![true; after.len()]);
    fn epoch<'a>(c: &'a [Vec<f64>; 3], owned: &'a [bool]) -> EpochPoints<'a> {
        EpochPoints {
            x: &c[0],
            y: &c[1],
            z: &c[2],
            owned,
        }
    }
    let keyed: Vec<(u64, Point3)> = cores
        .iter()
        .enumerate()
        .map(|(i, p)| (i as u64, *p))
        .collect();
    let data = Bounds::union(&bounds[..2]);
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(params.threads.value)
        .build()
        .map_err(|e| Error::Internal(format!("thread pool: {e}")))?;
    let results = pool.install(|| {
        compute(
            &epoch(&b, &ob),
            &epoch(&a, &oa),
            layout.anchor,
            layout.core_spacing,
            Some(&keyed),
            &params.m3c2(),
            &Extent::whole(data.min, data.max),
            None,
        )
    });
    let mut out = Columns::default();
    for k in &results {
        out.push(k, call.registration_error);
    }
    Ok((out, "memory"))
}

/// Write `points` as a binary little-endian PLY of doubles (the pipeline reads them unrounded).
fn write_ply(path: &Path, points: &[Point3]) -> talus::Result<()> {
    use std::io::Write;
    let f = std::fs::File::create(path).map_err(|e| Error::output(path, e))?;
    let mut w = std::io::BufWriter::with_capacity(1 << 20, f);
    let header = format!(
        "ply\nformat binary_little_endian 1.0\nelement vertex {}\nproperty double x\n\
         property double y\nproperty double z\nend_header\n",
        points.len()
    );
    let mut write = || -> std::io::Result<()> {
        w.write_all(header.as_bytes())?;
        for p in points {
            for v in p {
                w.write_all(&v.to_le_bytes())?;
            }
        }
        w.flush()
    };
    write().map_err(|e| Error::output(path, e))
}

/// A scratch folder removed when dropped.
struct Scratch(PathBuf);

impl Drop for Scratch {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// M3C2 through `talus compare --m3c2-only --align off`, the arrays written as PLY files into a
/// scratch folder under `workdir` (or the system's temporary folder); the results read back from
/// the run's M3C2 units, in the core points' order.
fn through_pipeline(
    before: &[Point3],
    after: &[Point3],
    cores: &[Point3],
    call: &M3c2Call,
) -> talus::Result<Columns> {
    static NEXT: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
    let base = call.workdir.clone().unwrap_or_else(std::env::temp_dir);
    let n = NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let dir = base.join(format!("talus-m3c2-{}-{n}", std::process::id()));
    std::fs::create_dir_all(&dir).map_err(|e| Error::output(&dir, e))?;
    let scratch = Scratch(dir);
    let file = |name: &str| scratch.0.join(name);
    write_ply(&file("epoch1.ply"), before)?;
    write_ply(&file("epoch2.ply"), after)?;
    write_ply(&file("corepoints.ply"), cores)?;
    let mut user = call.user.clone();
    user.align = Some("off".into());
    let opts = CompareOptions {
        before: file("epoch1.ply"),
        after: file("epoch2.ply"),
        out: file("out"),
        core_points: Some(file("corepoints.ply")),
        user,
        m3c2_only: true,
        // Its results are read from the M3C2 units below, after the run.
        keep_units: true,
        ..Default::default()
    };
    run_compare(&opts)?;
    let store = Store::open(&opts.out, false)?;
    let plan = Plan::load(&store.plan_path())?;
    let pool = talus::memory::pool_for(plan.params.memory_bytes.value);
    let ctx = talus::units::Ctx {
        plan: &plan,
        store: &store,
        progress: &|_| {},
        pool: &pool,
        reader: None,
    };
    let mut merged = Merged::new(&ctx, 0)?;
    let mut out = Columns::default();
    while let Some(k) = merged.next_result()? {
        out.push(&k, call.registration_error);
    }
    if out.distance.len() != cores.len() {
        return Err(Error::Internal(format!(
            "the pipeline gave {} results for {} core points",
            out.distance.len(),
            cores.len()
        )));
    }
    Ok(out)
}

/// M3C2 at `corepoints` between `epoch1` and `epoch2` (N × 3 float64, C order): a dict of
/// numpy arrays (see `talus.m3c2` for the meaning of every argument and output).
#[pyfunction]
#[pyo3(signature = (epoch1, epoch2, corepoints, params_json, registration_error, out_of_core, workdir))]
#[allow(clippy::too_many_arguments)]
fn m3c2<'py>(
    py: Python<'py>,
    epoch1: PyReadonlyArray2<'py, f64>,
    epoch2: PyReadonlyArray2<'py, f64>,
    corepoints: PyReadonlyArray2<'py, f64>,
    params_json: &str,
    registration_error: f64,
    out_of_core: Option<bool>,
    workdir: Option<PathBuf>,
) -> PyResult<Bound<'py, PyDict>> {
    let user = user_params(params_json)?;
    let call = M3c2Call {
        user,
        registration_error,
        out_of_core,
        workdir,
    };
    let (b, a, c) = (
        points("epoch1", &epoch1)?,
        points("epoch2", &epoch2)?,
        points("corepoints", &corepoints)?,
    );
    let (cols, route) = py.detach(|| m3c2_points(b, a, c, &call)).map_err(to_py)?;
    cols.into_dict(py, route)
}

/// The user's parameters from JSON (the Python side's keyword arguments): an unknown name or a
/// value of the wrong type is refused with serde's message.
fn user_params(json: &str) -> PyResult<UserParams> {
    serde_json::from_str(json).map_err(|e| InputError::new_err(format!("parameters: {e}")))
}

/// `talus compare BEFORE AFTER --out OUT` with `params_json`'s parameters; the summary's path.
#[pyfunction]
#[pyo3(signature = (before, after, out, params_json, config=None, core_points=None, before_mesh=None, after_mesh=None, resume=false, force=false, m3c2_only=false, tile_size=None))]
#[allow(clippy::too_many_arguments)]
fn compare(
    py: Python<'_>,
    before: PathBuf,
    after: PathBuf,
    out: PathBuf,
    params_json: &str,
    config: Option<PathBuf>,
    core_points: Option<PathBuf>,
    before_mesh: Option<PathBuf>,
    after_mesh: Option<PathBuf>,
    resume: bool,
    force: bool,
    m3c2_only: bool,
    tile_size: Option<f64>,
) -> PyResult<()> {
    let opts = CompareOptions {
        before,
        after,
        out,
        config,
        core_points,
        user: user_params(params_json)?,
        resume,
        force,
        before_mesh,
        after_mesh,
        m3c2_only,
        tile_size,
        ..Default::default()
    };
    py.detach(|| run_compare(&opts)).map_err(to_py)?;
    Ok(())
}

/// `talus campaign EPOCH... --out OUT` with `params_json`'s parameters.
#[pyfunction]
#[pyo3(signature = (epochs, out, params_json, config=None, baseline=false, resume=false, force=false, pair_clouds=false))]
#[allow(clippy::too_many_arguments)]
fn campaign(
    py: Python<'_>,
    epochs: Vec<PathBuf>,
    out: PathBuf,
    params_json: &str,
    config: Option<PathBuf>,
    baseline: bool,
    resume: bool,
    force: bool,
    pair_clouds: bool,
) -> PyResult<()> {
    let opts = CampaignOptions {
        epochs,
        out,
        config,
        user: user_params(params_json)?,
        baseline,
        resume,
        force,
        tile_size: None,
        // The intermediate units are released after the run, as the command line's default.
        keep_units: false,
        tiling_part: None,
        pair_clouds,
        executor: Default::default(),
    };
    py.detach(|| talus::commands::campaign::campaign(&opts))
        .map_err(to_py)?;
    Ok(())
}

/// Stop the running call at its next safe point (finished units are kept for `resume=True`).
#[pyfunction]
fn request_interrupt() {
    talus::interrupt::request();
}

/// Forget the interruption once the call it stopped has returned.
#[pyfunction]
fn reset_interrupt() {
    talus::interrupt::reset();
}

/// The progress lines the run printed since the last call.
static LINES: Mutex<Vec<String>> = Mutex::new(Vec::new());

/// Collect the stages' progress lines for [`take_progress`] instead of printing them (`on`), or
/// print them on the process's stderr again.
#[pyfunction]
fn capture_progress(on: bool) {
    if on {
        talus::progress::set_sink(Some(Box::new(|line: &str| {
            LINES
                .lock()
                .unwrap_or_else(|e| e.into_inner())
                .push(line.to_string());
        })));
    } else {
        talus::progress::set_sink(None);
    }
}

/// The progress lines collected since the last call.
#[pyfunction]
fn take_progress() -> Vec<String> {
    std::mem::take(&mut *LINES.lock().unwrap_or_else(|e| e.into_inner()))
}

#[pymodule]
fn _talus(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add("TalusError", py.get_type::<TalusError>())?;
    m.add("InputError", py.get_type::<InputError>())?;
    m.add_function(wrap_pyfunction!(m3c2, m)?)?;
    m.add_function(wrap_pyfunction!(compare, m)?)?;
    m.add_function(wrap_pyfunction!(campaign, m)?)?;
    m.add_function(wrap_pyfunction!(request_interrupt, m)?)?;
    m.add_function(wrap_pyfunction!(reset_interrupt, m)?)?;
    m.add_function(wrap_pyfunction!(capture_progress, m)?)?;
    m.add_function(wrap_pyfunction!(take_progress, m)?)?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
