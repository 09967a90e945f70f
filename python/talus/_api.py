"""The calls: argument checks and conversions here, the work in the native module ``_talus``."""

import json
import os
import sys
import threading

import numpy as np

from . import _talus
from ._result import Result

# The parameters of `talus compare` and `talus campaign` (their flags, with underscores).
PARAMS = (
    "point_spacing",
    "core_spacing",
    "normal_radius",
    "cyl_radius",
    "cyl_halflen",
    "reg_error",
    "min_points",
    "classes",
    "stable",
    "orientation",
    "align",
    "vegetation",
    "threshold",
    "smooth_k",
    "smooth_sigma",
    "eps",
    "cluster_min_points",
    "memory",
    "threads",
)

# py4dgeo's names for the same parameters.
ALIASES = {
    "normal_radii": "normal_radius",
    "max_distance": "cyl_halflen",
    "registration_error": "reg_error",
    "orientation_vector": "orientation",
}


def _points(name, a):
    """`a` as an N x 3 C-ordered float64 array, or a clear exception."""
    cloud = getattr(a, "cloud", None)  # a py4dgeo Epoch
    if cloud is not None and not isinstance(a, np.ndarray):
        a = cloud
    try:
        arr = np.asarray(a)
    except Exception as e:  # noqa: BLE001 - anything numpy cannot read
        raise TypeError(f"{name}: cannot read as an array of points: {e}") from None
    if arr.dtype.kind != "f":
        raise TypeError(
            f"{name}: expected floating-point coordinates (an N x 3 float64 array), "
            f"got dtype {arr.dtype}"
        )
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise ValueError(f"{name}: expected an N x 3 array of x, y, z, got shape {arr.shape}")
    if arr.shape[0] == 0:
        raise ValueError(f"{name}: no points")
    finite = np.isfinite(arr).all(axis=1)
    if not finite.all():
        row = int(np.flatnonzero(~finite)[0])
        raise ValueError(
            f"{name}: {int((~finite).sum())} point(s) with a NaN or infinite coordinate "
            f"(the first at row {row}: {arr[row].tolist()})"
        )
    return np.ascontiguousarray(arr, dtype=np.float64)


def _length(name, v):
    """One positive length, or None; py4dgeo's one-element sequences taken as their element."""
    if v is None:
        return None
    if isinstance(v, (list, tuple, np.ndarray)):
        vals = list(np.asarray(v, dtype=float).ravel())
        if len(vals) != 1:
            raise ValueError(
                f"{name}: talus computes each normal at one radius: give one value, got {len(vals)}"
            )
        v = vals[0]
    try:
        return float(v)
    except (TypeError, ValueError):
        raise TypeError(f"{name}: expected a number, got {v!r}") from None


def _orientation(v):
    """talus's orientation text of `v`: 'auto', 'up', 'toward:X,Y,Z' or a vector X,Y,Z."""
    if v is None:
        return None
    if isinstance(v, str):
        return v
    vec = np.asarray(v, dtype=float).ravel()
    if vec.shape != (3,):
        raise ValueError(f"orientation: expected 'auto', 'up', 'toward:X,Y,Z' or 3 numbers, got {v!r}")
    return ",".join(repr(float(x)) for x in vec)


def _size(v):
    if v is None or isinstance(v, str):
        return v
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    raise TypeError(f"memory: expected a size such as '2GiB' or a number of bytes, got {v!r}")


def _user_params(call, given):
    """The keyword arguments of `call` as talus's parameters (JSON), py4dgeo's names taken too."""
    out = {}
    for key, value in given.items():
        name = ALIASES.get(key, key)
        if name not in PARAMS:
            raise TypeError(
                f"{call}() got an unexpected keyword argument '{key}' "
                f"(talus's parameters: {', '.join(PARAMS)}; py4dgeo's names "
                f"{', '.join(ALIASES)} are taken too)"
            )
        if value is None:
            continue
        if name in out:
            raise TypeError(f"{call}(): '{key}' gives {name} a second time")
        if name == "orientation":
            value = _orientation(value)
        elif name == "memory":
            value = _size(value)
        elif name == "normal_radius":
            value = _length(key, value)
        elif name == "classes" and not isinstance(value, str):
            value = ",".join(str(int(c)) for c in value)
        elif name == "stable":
            value = os.fspath(value)
        out[name] = value
    return json.dumps(out)


def _flush(progress):
    lines = _talus.take_progress()
    if not progress:
        return
    for line in lines:
        if callable(progress):
            progress(line)
        else:
            print(line, file=sys.stderr, flush=True)


def _run(progress, fn, *args, **kwargs):
    """`fn(*args, **kwargs)` in a thread (it releases the GIL), with the main thread waiting so
    that Ctrl-C reaches it: the run is then asked to stop at its next safe point, waited for, and
    KeyboardInterrupt raised. Progress lines go to `progress` (True: sys.stderr, which a notebook
    shows; a callable: called with each line; False: dropped)."""
    box = {}

    def work():
        try:
            box["value"] = fn(*args, **kwargs)
        except BaseException as e:  # noqa: BLE001 - handed to the caller's thread
            box["error"] = e

    _talus.capture_progress(True)
    thread = threading.Thread(target=work, name="talus", daemon=True)
    thread.start()
    try:
        try:
            while thread.is_alive():
                thread.join(0.2)
                _flush(progress)
        except KeyboardInterrupt:
            _talus.request_interrupt()
            while thread.is_alive():
                try:
                    thread.join(0.2)
                except KeyboardInterrupt:
                    pass  # already stopping: wait for the safe point
            _talus.reset_interrupt()
            _flush(progress)
            raise KeyboardInterrupt(
                "talus: interrupted; the finished units are kept: the same call with "
                "resume=True goes on from them"
            ) from None
        _flush(progress)
    finally:
        _talus.capture_progress(False)
    err = box.get("error")
    if err is not None:
        if getattr(err, "exit_code", None) == 130:
            raise KeyboardInterrupt(f"talus: {err}") from None
        raise err
    return box["value"]


class M3C2Result:
    """M3C2 at each core point, in the core points' order.

    Iterates as ``(distances, uncertainties)``, the pair py4dgeo's ``M3C2.run()`` returns, with
    ``uncertainties`` in py4dgeo's layout (a structured array of ``lodetection``, ``spread1``,
    ``num_samples1``, ``spread2``, ``num_samples2``).

    Attributes (numpy arrays of length N, normals N x 3):
        distances: t2 - t1 along the normal, NaN where either cylinder is empty (or the other
            epoch lies beyond a given ``max_distance``: ``beyond_reach``).
        lodetection: LoD95 = 1.96 (sqrt(s1^2/n1 + s2^2/n2) + registration_error).
        significant: |distance| > lodetection.
        spread1, spread2: standard deviation of each epoch's points along the normal in the
            cylinder (the population's, as PDAL and CloudCompare; py4dgeo's is the sample's).
        num_samples1, num_samples2: points in each cylinder.
        normals: the oriented unit normals.
        beyond_reach: the other epoch lies beyond the given ``max_distance`` (distance NaN).
        sign_known: the data decides which side of the surface is out (``orientation='auto'``).
        route: 'memory' or 'pipeline' (out of core, through ``talus compare``'s tiles).
    """

    def __init__(self, d):
        self.distances = d["distances"]
        self.lodetection = d["lodetection"]
        self.significant = d["significant"]
        self.spread1 = d["spread1"]
        self.spread2 = d["spread2"]
        self.num_samples1 = d["num_samples1"]
        self.num_samples2 = d["num_samples2"]
        self.normals = d["normals"]
        self.beyond_reach = d["beyond_reach"]
        self.sign_known = d["sign_known"]
        self.route = d["route"]

    @property
    def uncertainties(self):
        u = np.empty(
            len(self.distances),
            dtype=[
                ("lodetection", "<f8"),
                ("spread1", "<f8"),
                ("num_samples1", "<i8"),
                ("spread2", "<f8"),
                ("num_samples2", "<i8"),
            ],
        )
        for name in u.dtype.names:
            u[name] = getattr(self, name)
        return u

    def __iter__(self):
        return iter((self.distances, self.uncertainties))

    def __len__(self):
        return len(self.distances)

    def to_dataframe(self):
        """The results as a pandas DataFrame, one row per core point."""
        import pandas as pd

        cols = {
            "distance": self.distances,
            "lodetection": self.lodetection,
            "significant": self.significant,
            "spread1": self.spread1,
            "spread2": self.spread2,
            "num_samples1": self.num_samples1,
            "num_samples2": self.num_samples2,
            "normal_x": self.normals[:, 0],
            "normal_y": self.normals[:, 1],
            "normal_z": self.normals[:, 2],
            "beyond_reach": self.beyond_reach,
            "sign_known": self.sign_known,
        }
        return pd.DataFrame(cols)

    def __repr__(self):
        ok = np.isfinite(self.distances)
        return (
            f"<talus.M3C2Result: {len(self)} core points, {int(ok.sum())} with a distance, "
            f"{int(self.significant.sum())} significant; {self.route}>"
        )


def m3c2(
    epoch1,
    epoch2,
    corepoints,
    normal_radii=None,
    cyl_radius=None,
    max_distance=None,
    orientation="up",
    *,
    orientation_vector=None,
    registration_error=0.0,
    min_points=None,
    point_spacing=None,
    memory=None,
    threads=None,
    out_of_core=None,
    workdir=None,
    progress=True,
):
    """M3C2 distances at `corepoints` between `epoch1` and `epoch2` (N x 3 float arrays in the
    same coordinates, or py4dgeo Epochs): the numbers ``talus compare --m3c2-only --align off
    --core-points`` gives for the same points and parameters.

    normal_radii: the radius of the PCA normal at each core point, on epoch 1 (a number, or
        py4dgeo's one-element sequence); None: 4 x the effective point spacing of epoch 1.
    cyl_radius: the cylinder's radius; None: 3 x the spacing.
    max_distance: the cylinder's half-length along the normal (py4dgeo's max_distance); where
        the other epoch lies beyond it, the distance is NaN and ``beyond_reach`` set. None:
        10 x cyl_radius as a search window, and where a cylinder holds one epoch alone, the
        other is sought on along the normal (talus's reach, see README).
    orientation: 'up' (n_z >= 0, py4dgeo's default orientation_vector), a vector (x, y, z)
        (n . v >= 0), 'toward:X,Y,Z' (toward a point, the scanner), or 'auto' (the survey's
        orientation field: runs through the pipeline). ``orientation_vector``: py4dgeo's name.
    registration_error: added to the LoD95 as 1.96 x it (py4dgeo's registration_error).
    min_points: fewer points than this in either cylinder: no distance (default 1).
    point_spacing: the effective spacing the derived parameters start from (default measured
        on epoch 1, as talus compare measures it).
    memory: the budget ('2GiB' default, or bytes). When both epochs need more (about 104 bytes
        a point), or ``out_of_core=True``, M3C2 runs out of core through talus compare's tiles,
        its files in a scratch folder under ``workdir`` (default: the system's temporary folder),
        removed afterwards.
    threads: worker threads (default: every core). The numbers do not depend on it.
    progress: True (lines on sys.stderr), False, or a callable taking each line.

    Returns an :class:`M3C2Result`; ``distances, uncertainties = talus.m3c2(...)`` as py4dgeo.
    """
    if orientation_vector is not None:
        if orientation not in (None, "up"):
            raise TypeError("m3c2(): give orientation or orientation_vector, not both")
        orientation = orientation_vector
    e1 = _points("epoch1", epoch1)
    e2 = _points("epoch2", epoch2)
    cores = _points("corepoints", corepoints)
    params = _user_params(
        "m3c2",
        {
            "normal_radii": normal_radii,
            "cyl_radius": _length("cyl_radius", cyl_radius),
            "max_distance": _length("max_distance", max_distance),
            "orientation": orientation,
            "min_points": min_points,
            "point_spacing": _length("point_spacing", point_spacing),
            "memory": memory,
            "threads": threads,
        },
    )
    reg = float(registration_error)
    if not (np.isfinite(reg) and reg >= 0):
        raise ValueError(f"registration_error: expected a number >= 0, got {registration_error!r}")
    workdir = None if workdir is None else os.fspath(workdir)
    d = _run(
        progress, _talus.m3c2, e1, e2, cores, params, reg, out_of_core, workdir
    )
    return M3C2Result(d)


def _path(p):
    return None if p is None else os.fspath(p)


def compare(
    before,
    after,
    out,
    *,
    config=None,
    core_points=None,
    before_mesh=None,
    after_mesh=None,
    resume=False,
    force=False,
    m3c2_only=False,
    progress=True,
    tile_size=None,
    **params,
):
    """``talus compare BEFORE AFTER --out OUT`` with the parameters given as keyword arguments
    (the flags' names with underscores: ``normal_radius=0.5, orientation='up', memory='4GiB'``;
    py4dgeo's ``normal_radii``, ``max_distance``, ``registration_error`` are taken too).
    ``tile_size`` forces the tiles' side, as the command line's hidden --tile-size (for tests:
    the memory budget plans them otherwise). Returns the :class:`Result` of OUT."""
    _run(
        progress,
        _talus.compare,
        _path(before),
        _path(after),
        _path(out),
        _user_params("compare", params),
        config=_path(config),
        core_points=_path(core_points),
        before_mesh=_path(before_mesh),
        after_mesh=_path(after_mesh),
        resume=bool(resume),
        force=bool(force),
        m3c2_only=bool(m3c2_only),
        tile_size=None if tile_size is None else float(tile_size),
    )
    return Result(out)


def campaign(
    epochs,
    out,
    *,
    config=None,
    baseline=False,
    resume=False,
    force=False,
    pair_clouds=False,
    progress=True,
    **params,
):
    """``talus campaign EPOCH... --out OUT`` (the surveys in date order, or a folder, as the
    command takes them) with the parameters as keyword arguments. Returns the :class:`Result`
    of OUT. ``pair_clouds=True`` is ``--pair-clouds``: every pair gets its own m3c2.laz."""
    if isinstance(epochs, (str, os.PathLike)):
        epochs = [epochs]
    _run(
        progress,
        _talus.campaign,
        [os.fspath(e) for e in epochs],
        _path(out),
        _user_params("campaign", params),
        config=_path(config),
        baseline=bool(baseline),
        resume=bool(resume),
        force=bool(force),
        pair_clouds=bool(pair_clouds),
    )
    return Result(out)
