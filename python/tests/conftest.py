"""Fixtures of the Python tests: the talus binary, and the data of benches/py/make_data.py.

The `talus` command line the numbers are checked against is TALUS_BIN, else the newest of the
repository's target/{debug,release}/talus; without one the tests fail (they check nothing
without it).
"""

import os
import subprocess
import sys
from pathlib import Path

import laspy
import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[2]


def talus_bin():
    env = os.environ.get("TALUS_BIN")
    if env:
        return env
    found = []
    for d in (os.environ.get("CARGO_TARGET_DIR"), REPO / "target"):
        if d:
            found += [p for p in (Path(d) / "debug/talus", Path(d) / "release/talus") if p.is_file()]
    if not found:
        pytest.fail("no talus binary: set TALUS_BIN or build it (cargo build --bin talus)")
    return str(max(found, key=lambda p: p.stat().st_mtime))


@pytest.fixture(scope="session")
def talus_cli():
    return talus_bin()


def run_cli(*args, ok=True):
    """Run the talus binary; its CompletedProcess (stderr as text)."""
    p = subprocess.run([talus_bin(), *map(str, args)], capture_output=True, text=True)
    if ok and p.returncode != 0:
        raise AssertionError(f"talus {' '.join(map(str, args))} failed:\n{p.stderr}")
    return p


def read_xyz(path):
    las = laspy.read(path)
    return np.column_stack([las.x, las.y, las.z])


@pytest.fixture(scope="session")
def bench_data(tmp_path_factory):
    """The benchmark's rough surface (benches/py/make_data.py), smaller: 2 x 450,000 points (more
    than the 400,000 talus measures the spacing on whole: its window is measured, as on large
    surveys) and a grid of 19,881 core points; the arrays as laspy reads the files."""
    d = tmp_path_factory.mktemp("bench-data")
    subprocess.run(
        [
            sys.executable,
            str(REPO / "benches/py/make_data.py"),
            str(d),
            "--points",
            "450000",
            "--cores",
            "20000",
        ],
        check=True,
    )
    return {
        "dir": d,
        "before": d / "before.las",
        "after": d / "after.las",
        "cores": d / "cores.las",
        "e1": read_xyz(d / "before.las"),
        "e2": read_xyz(d / "after.las"),
        "c": read_xyz(d / "cores.las"),
    }
