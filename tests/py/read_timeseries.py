"""Independent readers for talus's tests: a campaign's timeseries.parquet read with pyarrow,
its timeseries.laz with laspy, compared value by value; print JSON.

Usage: read_timeseries.py DIR [--pairs] [--against OTHER]

Reads DIR/timeseries.parquet (pyarrow) and DIR/timeseries.laz (laspy) and checks, for every
row: x, y and z equal to the LAS's bit for bit; each distance column d_<before>_<after> equal bit
for bit to the LAS's extra dimension of that name when the LAS has it, a null where the LAS has
NaN and nowhere else. With --pairs also each pair's DIR/pairs/<before>_<after>/m3c2.laz: its
points are the same, in the same order, and its m3c2_distance (float32) is the column (NaN as
null); a pair without m3c2.laz (a campaign run without --pair-clouds) is compared through its
terrain.bin (the viewer's file, every core point when there are at most 2M): the distances
(float32, after the positions or alone where view.json names `positions` elsewhere) are the
column, and the positions (float32 offsets from view.json's origin) within 1 mm of x, y, z.
With --against OTHER also OTHER/timeseries.laz, the time series of another campaign of the same
first survey (so the same core points, in the same order): each extra dimension of it is the
column of that name here.

Prints the Parquet's facts (rows, row groups, column names, types and nullability, created_by,
key-value metadata, nulls per column), the LAS's (points, extra dimensions), how many values were
compared against each source, and the first mismatches (empty when everything agrees).
"""

import json
import os
import sys

import laspy
import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq


def bits(a):
    return np.ascontiguousarray(a, dtype=np.float64).view(np.uint64)


def compare(name, column, values, mismatches):
    """A Parquet column (pyarrow ChunkedArray) against float64 values where NaN means null:
    the number of values compared."""
    nulls = column.is_null().to_numpy(zero_copy_only=False)
    nan = np.isnan(values)
    if len(values) != len(column):
        mismatches.append(f"{name}: {len(column)} rows, {len(values)} values")
        return 0
    bad = np.flatnonzero(nulls != nan)
    if bad.size:
        i = int(bad[0])
        mismatches.append(f"{name}: row {i}: null {bool(nulls[i])}, value {values[i]!r}")
    got = column.to_numpy(zero_copy_only=False)
    if values.dtype == np.float32:
        # m3c2.laz holds its distances as float32: the column rounded to that width.
        got = got.astype(np.float32)
    keep = ~nulls & ~nan
    bad = np.flatnonzero(keep & (bits(got) != bits(values)))
    if bad.size:
        i = int(bad[0])
        mismatches.append(f"{name}: row {i}: {got[i]!r} against {values[i]!r}")
    return len(values)


def pair_file(folder, column, name):
    """DIR/pairs/<before>_<after>/name of the pair whose column is `column`."""
    return os.path.join(folder, "pairs", column[len("d_"):], name)


def compare_terrain(folder, name, column, xyz, mismatches):
    """A pair's terrain.bin (the viewer's) against its column and the core points: the values
    compared (0 when the terrain is a sample, not every core point)."""
    with open(pair_file(folder, name, "view.json")) as f:
        view = json.load(f)
    n = view["points"]
    if n != len(column):
        return 0
    raw = np.fromfile(pair_file(folder, name, "terrain.bin"), dtype="<f4")
    if "positions" in view:
        where = os.path.normpath(os.path.join(os.path.dirname(pair_file(folder, name, "x")), view["positions"]))
        positions = np.fromfile(where, dtype="<f4")[: 3 * n]
        distances = raw
    else:
        positions, distances = raw[: 3 * n], raw[3 * n :]
    if len(distances) != n or len(positions) != 3 * n:
        mismatches.append(f"{name}: terrain.bin holds {raw.size} floats for {n} points")
        return 0
    p = positions.reshape(n, 3).astype(np.float64) + np.asarray(view["origin"])
    for a, axis in enumerate("xyz"):
        off = np.abs(p[:, a] - xyz[axis])
        if off.max(initial=0.0) > 1e-3:
            mismatches.append(f"{name}: terrain.bin's {axis} off by {off.max()} m")
    return compare(f"{name} (terrain.bin)", column, distances.astype(np.float32), mismatches)


def main():
    folder = sys.argv[1]
    args = sys.argv[2:]
    with_pairs = "--pairs" in args
    other = args[args.index("--against") + 1] if "--against" in args else None
    pf = pq.ParquetFile(os.path.join(folder, "timeseries.parquet"))
    table = pf.read()
    meta = pf.metadata
    las = laspy.read(os.path.join(folder, "timeseries.laz"))
    extra = list(las.point_format.extra_dimension_names)
    mismatches = []
    compared = {"laz": 0, "pairs": 0, "terrain": 0, "against": 0}
    xyz = {"x": np.asarray(las.x), "y": np.asarray(las.y), "z": np.asarray(las.z)}
    for name, values in xyz.items():
        compared["laz"] += compare(name, table.column(name), values, mismatches)
    distances = [n for n in table.column_names if n not in xyz]
    for name in distances:
        column = table.column(name)
        if name in extra:
            compared["laz"] += compare(name, column, np.asarray(las[name]), mismatches)
        if with_pairs and not os.path.exists(pair_file(folder, name, "m3c2.laz")):
            compared["terrain"] += compare_terrain(folder, name, column, xyz, mismatches)
        elif with_pairs:
            pair = pair_file(folder, name, "m3c2.laz")
            m = laspy.read(pair)
            for axis in "xyz":
                if not np.array_equal(bits(getattr(m, axis)), bits(xyz[axis])):
                    mismatches.append(f"{pair}: its {axis} are not the time series'")
            compared["pairs"] += compare(
                f"{name} (m3c2.laz)", column, np.asarray(m["m3c2_distance"]), mismatches
            )
    if other is not None:
        theirs = laspy.read(os.path.join(other, "timeseries.laz"))
        for name in theirs.point_format.extra_dimension_names:
            if name not in table.column_names:
                mismatches.append(f"{other}: {name} is no column here")
                continue
            compared["against"] += compare(
                f"{name} ({other})", table.column(name), np.asarray(theirs[name]), mismatches
            )
    schema = table.schema
    out = {
        "rows": table.num_rows,
        "row_groups": meta.num_row_groups,
        "rows_per_group": [meta.row_group(i).num_rows for i in range(meta.num_row_groups)],
        "columns": table.column_names,
        "types": sorted({str(f.type) for f in schema}),
        "nullable": [f.nullable for f in schema],
        "created_by": meta.created_by,
        "format_version": meta.format_version,
        "metadata": {
            k.decode(): v.decode() for k, v in (meta.metadata or {}).items()
        },
        "nulls": {n: table.column(n).null_count for n in table.column_names},
        "laz": {
            "points": int(las.header.point_count),
            "extra_dims": extra,
            "version": f"{las.header.version.major}.{las.header.version.minor}",
        },
        "compared": compared,
        "mismatches": mismatches[:20],
        "pyarrow": pa.__version__,
        "laspy": laspy.__version__,
    }
    json.dump(out, sys.stdout)


if __name__ == "__main__":
    main()
