"""talus.m3c2 on numpy arrays against `talus compare --m3c2-only` (the same numbers, bit for bit)
and against py4dgeo (within the agreement benches/m3c2_vs_py4dgeo.sh reports) on the same data."""

import laspy
import numpy as np
import py4dgeo
import pytest

import talus
from conftest import run_cli


# The benchmark's parameters (benches/m3c2_vs_py4dgeo.sh), as flags and as py4dgeo's arguments.
BENCH_FLAGS = ("--normal-radius", "1.0", "--cyl-radius", "0.5", "--cyl-halflen", "3.0")
BENCH = dict(normal_radii=(1.0,), cyl_radius=0.5, max_distance=3.0)


def cli_m3c2(data, out, *flags, reg_error="0"):
    """m3c2.laz of `talus compare --m3c2-only --align off --reg-error R --orientation up` on the
    benchmark files with the core-point file, and `flags`."""
    run_cli(
        "compare",
        data["before"],
        data["after"],
        "--out",
        out,
        "--core-points",
        data["cores"],
        "--orientation",
        "up",
        "--m3c2-only",
        "--align",
        "off",
        "--reg-error",
        reg_error,
        *flags,
    )
    return laspy.read(out / "m3c2.laz")


def assert_same_as_cli(r, las, cores):
    """Every output of `r` equal to m3c2.laz's, row for row (NaN where it has NaN)."""
    xyz = np.column_stack([las.x, las.y, las.z])
    assert len(r) == len(las.points) == len(cores)
    # m3c2.laz keeps the core points' order, at the core file's scale (0.1 mm).
    assert np.abs(xyz - cores).max() <= 0.5e-4 + 1e-9
    # m3c2.laz holds distances, LoDs and spreads as float32 (CloudCompare's width): the
    # in-process float64 values rounded to it, exactly.
    f32 = np.float32
    np.testing.assert_array_equal(r.distances.astype(f32), np.asarray(las.m3c2_distance))
    np.testing.assert_array_equal(r.lodetection.astype(f32), np.asarray(las.m3c2_uncertainty))
    np.testing.assert_array_equal(r.significant, np.asarray(las.m3c2_significant) == 1)
    np.testing.assert_array_equal(r.spread1.astype(f32), np.asarray(las.m3c2_std_dev1))
    np.testing.assert_array_equal(r.spread2.astype(f32), np.asarray(las.m3c2_std_dev2))
    np.testing.assert_array_equal(r.num_samples1, np.asarray(las.m3c2_count1))
    np.testing.assert_array_equal(r.num_samples2, np.asarray(las.m3c2_count2))
    np.testing.assert_array_equal(r.beyond_reach, np.asarray(las.m3c2_beyond_reach) == 1)
    np.testing.assert_array_equal(r.sign_known, np.asarray(las.normal_sign_unknown) == 0)
    # m3c2.laz stores normals as float32.
    n = np.column_stack([las.normal_x, las.normal_y, las.normal_z])
    np.testing.assert_array_equal(r.normals.astype(np.float32), n)
    # Not a comparison of nothing: most core points have a distance, some are significant.
    assert np.isfinite(r.distances).mean() > 0.95
    assert r.significant.sum() > 100


def test_same_numbers_as_cli_with_py4dgeo_parameters(bench_data, tmp_path):
    las = cli_m3c2(bench_data, tmp_path / "cli", *BENCH_FLAGS)
    r = talus.m3c2(bench_data["e1"], bench_data["e2"], bench_data["c"], **BENCH)
    assert r.route == "memory"
    assert_same_as_cli(r, las, bench_data["c"])


def test_same_numbers_as_cli_with_derived_parameters(bench_data, tmp_path):
    """No radii given: both measure epoch 1's spacing and derive the same radii, half-length
    (a search window, with the walk along the normal) and local frame."""
    las = cli_m3c2(bench_data, tmp_path / "cli")
    r = talus.m3c2(bench_data["e1"], bench_data["e2"], bench_data["c"])
    assert r.route == "memory"
    assert_same_as_cli(r, las, bench_data["c"])


def test_out_of_core_same_numbers(bench_data, tmp_path):
    """Through the tiled pipeline (as when the arrays exceed the budget): the numbers of the
    in-memory route, and so the command line's; the distances, spreads and normals rounded to
    float32, as the pipeline's results store them, to the last bit."""
    args = (bench_data["e1"], bench_data["e2"], bench_data["c"])
    mem = talus.m3c2(*args, **BENCH)
    tiled = talus.m3c2(*args, out_of_core=True, workdir=tmp_path, **BENCH)
    assert (mem.route, tiled.route) == ("memory", "pipeline")
    for name in (
        "lodetection",
        "significant",
        "num_samples1",
        "num_samples2",
        "beyond_reach",
        "sign_known",
    ):
        np.testing.assert_array_equal(getattr(tiled, name), getattr(mem, name), err_msg=name)
    for name in ("distances", "spread1", "spread2", "normals"):
        rounded = getattr(mem, name).astype(np.float32).astype(np.float64)
        np.testing.assert_array_equal(getattr(tiled, name), rounded, err_msg=name)
    assert list(tmp_path.iterdir()) == [], "the scratch folder is removed"


def test_registration_error_in_lod(bench_data, tmp_path):
    las = cli_m3c2(bench_data, tmp_path / "cli", *BENCH_FLAGS, reg_error="0.01")
    r = talus.m3c2(
        bench_data["e1"], bench_data["e2"], bench_data["c"], registration_error=0.01, **BENCH
    )
    # m3c2.laz holds the LoD as float32.
    np.testing.assert_array_equal(
        r.lodetection.astype(np.float32), np.asarray(las.m3c2_uncertainty)
    )
    np.testing.assert_array_equal(r.significant, np.asarray(las.m3c2_significant) == 1)


def test_agrees_with_py4dgeo(bench_data, tmp_path):
    """py4dgeo's M3C2 with the benchmark's parameters, on the same arrays (its Epochs passed to
    talus.m3c2 as they are): the agreement benches/m3c2_vs_py4dgeo.sh reports on grid core
    points (benches/README.md): every count identical, |delta d| 0.0000 mm (below 0.05 um)."""
    py4dgeo.set_py4dgeo_logfile(str(tmp_path / "py4dgeo.log"))
    ep1, ep2 = py4dgeo.Epoch(bench_data["e1"]), py4dgeo.Epoch(bench_data["e2"])
    cores = bench_data["c"]
    m = py4dgeo.M3C2(
        epochs=(ep1, ep2),
        corepoints=cores,
        normal_radii=(1.0,),
        cyl_radius=0.5,
        max_distance=3.0,
        orientation_vector=np.array([0.0, 0.0, 1.0]),
        cloud_for_normals=ep1,
    )
    d_p, u_p = m.run()
    r = talus.m3c2(ep1, ep2, cores, **BENCH)
    d_t, u_t = r
    np.testing.assert_array_equal(np.isfinite(d_t), np.isfinite(d_p))
    both = np.isfinite(d_t)
    assert both.mean() > 0.95
    np.testing.assert_array_equal(u_t["num_samples1"], u_p["num_samples1"])
    np.testing.assert_array_equal(u_t["num_samples2"], u_p["num_samples2"])
    dd = np.abs(d_t - d_p)[both]
    assert dd.max() < 5e-8, f"max |delta d| {dd.max():.3e} m"
    # The normals: the same PCA of the same points, up to rounding.
    n_p = m.corepoint_normals
    cos = np.abs(np.einsum("ij,ij->i", r.normals, n_p))
    ok = np.isfinite(cos)
    assert ok.mean() > 0.95
    ang = np.degrees(np.arccos(np.clip(cos[ok], 0.0, 1.0)))
    assert ang.max() < 1e-4, f"max normal angle {ang.max():.3e} deg"


def test_bad_arrays_raise_clear_exceptions(bench_data):
    e1, e2, c = bench_data["e1"], bench_data["e2"], bench_data["c"][:10]
    with pytest.raises(TypeError, match=r"epoch2: expected floating-point coordinates.*int64"):
        talus.m3c2(e1, e2.astype(np.int64), c)
    with pytest.raises(ValueError, match=r"corepoints: expected an N x 3 array.*\(10, 2\)"):
        talus.m3c2(e1, e2, c[:, :2])
    bad = c.copy()
    bad[3, 2] = np.nan
    with pytest.raises(ValueError, match=r"corepoints: 1 point\(s\) with a NaN .* row 3"):
        talus.m3c2(e1, e2, bad)
    with pytest.raises(ValueError, match="epoch1: no points"):
        talus.m3c2(np.empty((0, 3)), e2, c)
    with pytest.raises(talus.InputError, match="the epochs do not overlap"):
        talus.m3c2(e1, e2 + [1000.0, 0.0, 0.0], c)
    with pytest.raises(ValueError, match="one radius"):
        talus.m3c2(e1, e2, c, normal_radii=(0.5, 1.0))
    with pytest.raises(TypeError, match="unexpected keyword argument 'cyl_radii'"):
        talus.compare("a.las", "b.las", "out", cyl_radii=1.0)


def test_bad_parameter_is_talus_error_with_its_message(bench_data, tmp_path):
    """A negative radius: the exception carries the message the command line prints."""
    p = run_cli(
        "compare",
        bench_data["before"],
        bench_data["after"],
        "--out",
        tmp_path / "cli",
        "--cyl-radius=-1",
        ok=False,
    )
    assert p.returncode == 2
    message = p.stderr.strip().splitlines()[-1]
    with pytest.raises(talus.InputError) as e:
        talus.m3c2(bench_data["e1"], bench_data["e2"], bench_data["c"][:10], cyl_radius=-1.0)
    assert message == f"talus: error: {e.value}"
    assert e.value.exit_code == 2
    assert isinstance(e.value, talus.TalusError)
