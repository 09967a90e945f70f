"""talus.compare / talus.open on files against the command line: the same outputs, the events
DataFrame equal to events.csv, errors as exceptions with the command line's message, Ctrl-C
stopping a run that resume=True then finishes."""

import csv
import json
import math
import signal
import subprocess
import sys
import time

import geopandas as gpd
import numpy as np
import pytest

import talus
from conftest import run_cli

# Small tiles and a fine core grid: many units, so that an interruption falls between two.
TILED = ["--tile-size", "5", "--core-spacing", "0.25"]


@pytest.fixture(scope="module")
def cliff(tmp_path_factory):
    """`talus synth cliff` (100,000 points an epoch, two rockfall scars and a debris fan) and the
    command line's comparison of it, with small tiles."""
    d = tmp_path_factory.mktemp("cliff")
    run_cli("synth", "cliff", "--out", d / "scene", "--points", "100000")
    before, after = d / "scene/before.laz", d / "scene/after.laz"
    run_cli("compare", before, after, "--out", d / "cli", *TILED)
    return {"dir": d, "before": before, "after": after, "cli": d / "cli"}


def csv_rows(path):
    with open(path, newline="", encoding="utf-8") as f:
        return list(csv.DictReader(f))


def assert_frame_is_csv(df, path):
    """Every cell of `df` is the value of the CSV file's field, read with the csv module:
    true/false as booleans, numbers as numbers (an empty field: missing), text as text."""
    rows = csv_rows(path)
    with open(path, encoding="utf-8") as f:
        header = f.readline().strip().split(",")
    assert [c for c in df.columns if c != "geometry"] == header
    assert len(df) == len(rows) > 0
    for i, row in enumerate(rows):
        for col, text in row.items():
            v = df[col].iloc[i]
            if text in ("true", "false"):
                assert isinstance(v, (bool, np.bool_)) and bool(v) is (text == "true"), (i, col, v)
                continue
            try:
                number = float(text)
            except ValueError:
                number = None
            if number is not None:
                assert float(v) == number, (i, col, v, text)
            elif text == "" and not isinstance(v, str):
                assert math.isnan(v), (i, col, v)
            else:
                assert v == text, (i, col, v, text)


def test_compare_same_outputs_as_cli_and_events_frame(cliff, tmp_path):
    lines = []
    out = tmp_path / "py"
    res = talus.compare(
        cliff["before"],
        cliff["after"],
        out,
        tile_size=5,
        core_spacing=0.25,
        progress=lines.append,
    )
    # The outputs the command line wrote for the same inputs and parameters.
    for name in ("events.csv", "events.geojson", "event_regions.geojson", "m3c2.laz"):
        assert (out / name).read_bytes() == (cliff["cli"] / name).read_bytes(), name
    # Progress: a line per stage, as the command line prints them.
    assert any(line.startswith("talus: pass 2: normals and M3C2:") for line in lines), lines
    assert res.kind == "compare"
    with open(out / "summary.json", encoding="utf-8") as f:
        assert res.summary == json.load(f)
    assert res.summary["events"] == len(res.events) > 0
    assert_frame_is_csv(res.events, out / "events.csv")
    # talus.open reads the same folder the same way.
    again = talus.open(out)
    assert again.summary == res.summary
    assert again.events.equals(res.events)


def test_geodataframe_when_geopandas_is_present(cliff):
    ev = talus.open(cliff["cli"]).events
    assert isinstance(ev, gpd.GeoDataFrame)
    with open(cliff["cli"] / "events.geojson", encoding="utf-8") as f:
        features = json.load(f)["features"]
    for (_, row), feat in zip(ev.iterrows(), features):
        assert row["id"] == feat["properties"]["id"]
        x, y = feat["geometry"]["coordinates"][:2]
        assert abs(row.geometry.x - x) <= 5e-5 and abs(row.geometry.y - y) <= 5e-5


def test_missing_input_is_input_error_with_cli_message(cliff, tmp_path):
    missing = tmp_path / "nope.laz"
    p = run_cli("compare", missing, cliff["after"], "--out", tmp_path / "cli", ok=False)
    assert p.returncode == 2
    last = p.stderr.strip().splitlines()[-1]
    with pytest.raises(talus.InputError) as e:
        talus.compare(missing, cliff["after"], tmp_path / "py")
    assert str(e.value) in last and str(missing) in str(e.value)
    assert e.value.exit_code == 2
    with pytest.raises(talus.InputError, match="no talus result here"):
        talus.open(tmp_path)


CHILD = """
import sys, talus
try:
    talus.compare(sys.argv[1], sys.argv[2], sys.argv[3], tile_size=5, core_spacing=0.25)
except KeyboardInterrupt as e:
    print("KeyboardInterrupt:", e, file=sys.stderr, flush=True)
    sys.exit(3)
sys.exit(0)
"""


def test_ctrl_c_stops_cleanly_and_resume_finishes(cliff, tmp_path):
    """SIGINT (Ctrl-C) to a Python process in talus.compare, once its tiling is done: it raises
    KeyboardInterrupt, publishes nothing and keeps its units; resume=True then gives the outputs
    of an uninterrupted run."""
    out = tmp_path / "run"
    child = subprocess.Popen(
        [sys.executable, "-c", CHILD, str(cliff["before"]), str(cliff["after"]), str(out)],
        stderr=subprocess.PIPE,
        text=True,
    )
    seen = []
    for line in child.stderr:
        seen.append(line)
        if line.startswith("talus: pass 1: tiling:"):
            break
    else:
        pytest.fail("no tiling line: " + "".join(seen))
    child.send_signal(signal.SIGINT)
    t = time.monotonic()
    rest = child.stderr.read()
    assert child.wait(60) == 3, "".join(seen) + rest
    assert time.monotonic() - t < 30
    assert "KeyboardInterrupt: talus: interrupted; the finished units are kept" in rest, rest
    assert "pass 2: normals and M3C2" not in "".join(seen) + rest, "the run was not cut short"
    assert not (out / "summary.json").exists() and not (out / "events.csv").exists()
    assert any((out / ".talus/units").rglob("record.json")), "finished units kept"
    lines = []
    talus.compare(
        cliff["before"],
        cliff["after"],
        out,
        tile_size=5,
        core_spacing=0.25,
        resume=True,
        progress=lines.append,
    )
    assert any("reused" in line for line in lines), lines
    for name in ("events.csv", "events.geojson", "m3c2.laz"):
        assert (out / name).read_bytes() == (cliff["cli"] / name).read_bytes(), name


def test_campaign_same_outputs_as_cli(tmp_path):
    """`talus synth campaign` (3 surveys of a cliff): talus.campaign writes the command line's
    tables; its events, pairs and per-pair results read as DataFrames equal to the files."""
    run_cli("synth", "campaign", "--out", tmp_path / "data", "--epochs", "3", "--points", "40000")
    surveys = sorted((tmp_path / "data").glob("survey_*.laz"))
    run_cli("campaign", *surveys, "--out", tmp_path / "cli")
    res = talus.campaign(surveys, tmp_path / "py", progress=False)
    for name in ("events.csv", "magnitude_frequency.csv"):
        assert (tmp_path / "py" / name).read_bytes() == (tmp_path / "cli" / name).read_bytes(), name
    # campaign.csv: the same but for each pair's run time.
    untimed = [
        [{k: v for k, v in row.items() if k != "seconds"} for row in csv_rows(tmp_path / d / "campaign.csv")]
        for d in ("py", "cli")
    ]
    assert untimed[0] == untimed[1]
    assert res.kind == "campaign"
    assert_frame_is_csv(res.events, tmp_path / "py/events.csv")
    assert isinstance(res.events, gpd.GeoDataFrame)
    table = res.campaign_table
    assert len(table) == 2 and len(res.pairs) == 2
    for label, pair in res.pairs.items():
        assert pair.kind == "compare"
        assert (res.events["pair"] == label).sum() == len(pair.events)
        assert_frame_is_csv(pair.events, tmp_path / "py/pairs" / label / "events.csv")
