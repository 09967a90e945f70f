"""The outputs of a finished run (a `compare`'s or a `campaign`'s DIR), read as Python objects."""

import builtins
import json
import os
from pathlib import Path

# This module defines open(dir) (talus.open): files are opened with the builtin.
_open = builtins.open


class Result:
    """The outputs in `dir` of ``talus compare`` or ``talus campaign``.

    Attributes:
        dir: the folder (a :class:`pathlib.Path`).
        summary: summary.json as a dict.
        events: events.csv as a pandas DataFrame, one row per event (a geopandas GeoDataFrame
            with each event's centroid as its Point geometry, in the run's CRS when it has an
            EPSG code, when geopandas is installed); empty with its columns when there is none.
        kind: 'compare' or 'campaign'.
        pairs: a campaign's pairs, label -> Result of ``pairs/<label>`` (empty for a compare).
        campaign_table: a campaign's campaign.csv (one row per pair) as a DataFrame, else None.
    """

    def __init__(self, dir):
        self.dir = Path(dir)
        marker = self.dir / "summary.json"
        if not marker.is_file():
            from ._talus import InputError

            raise InputError(
                f"{self.dir}: no talus result here (no summary.json): a run that was "
                "interrupted or failed publishes nothing; run it again with resume=True"
            )
        with _open(marker, encoding="utf-8") as f:
            self.summary = json.load(f)
        self.kind = "campaign" if (self.dir / "campaign.csv").is_file() else "compare"
        self._events = None

    @property
    def events(self):
        if self._events is None:
            self._events = read_events(self.dir)
        return self._events

    @property
    def pairs(self):
        root = self.dir / "pairs"
        if self.kind != "campaign" or not root.is_dir():
            return {}
        return {
            p.name: Result(p) for p in sorted(root.iterdir()) if (p / "summary.json").is_file()
        }

    @property
    def campaign_table(self):
        if self.kind != "campaign":
            return None
        import pandas as pd

        return pd.read_csv(self.dir / "campaign.csv")

    def __repr__(self):
        n = len(self.events)
        return f"<talus.Result ({self.kind}) {self.dir}: {n} event(s)>"


def read_events(dir):
    """events.csv of `dir` as a DataFrame (a GeoDataFrame with geopandas)."""
    import pandas as pd

    path = Path(dir) / "events.csv"
    # Text stays text (volume_note: "" is no note); the rest as pandas reads numbers and
    # true/false.
    df = pd.read_csv(path, keep_default_na=False, na_values={c: [""] for c in _numeric(path)})
    try:
        import geopandas as gpd
    except ImportError:
        return df
    crs = _epsg(Path(dir))
    xyz = [c for c in ("x", "y", "z") if c in df.columns]
    if len(xyz) < 2:
        return gpd.GeoDataFrame(df)
    geometry = gpd.points_from_xy(*(df[c] for c in xyz), crs=crs)
    return gpd.GeoDataFrame(df, geometry=geometry, crs=crs)


def _numeric(path):
    """The columns of events.csv whose empty fields mean 'no value' (all but the text ones)."""
    with _open(path, encoding="utf-8") as f:
        header = f.readline().strip().split(",")
    return [c for c in header if c not in ("kind", "volume_note", "pair", "track")]


def _epsg(dir):
    """The EPSG code of the run's CRS as 'EPSG:n', or None."""
    s = {}
    try:
        with _open(dir / "summary.json", encoding="utf-8") as f:
            s = json.load(f)
    except (OSError, ValueError):
        return None
    found = _find_key(s, "epsg")
    return f"EPSG:{found}" if isinstance(found, int) else None


def _find_key(obj, key):
    if isinstance(obj, dict):
        if key in obj and obj[key] is not None:
            return obj[key]
        for v in obj.values():
            r = _find_key(v, key)
            if r is not None:
                return r
    elif isinstance(obj, list):
        for v in obj:
            r = _find_key(v, key)
            if r is not None:
                return r
    return None


def open(dir):  # noqa: A001 - talus.open(dir), as the issue names it
    """The :class:`Result` of a finished run in `dir`."""
    return Result(os.fspath(dir))
