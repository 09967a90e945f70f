"""Deterministic test data for the talus vs py4dgeo M3C2 benchmark.

Writes into OUTDIR:
  before.las  epoch 1: N points of a rough surface (uniform random XY over 100 m x 100 m)
  after.las   epoch 2: N points of the same surface, sampled independently, with planted
              bumps and pits (Gaussian, 0.2-1 m)
  cores.las   the core points: with --core-layout grid (default) a regular grid on the
              noise-free surface (round(sqrt(cores))² points, in row order); with
              --core-layout epoch1 a random subset of epoch 1 in random order (py4dgeo then
              miscounts: its cylinder segment boundary falls on t = 0, where every such core
              point's own epoch-1 point lies; see benches/README.md)
  data.json   the generation parameters and the planted changes

All three files are LAS 1.4, point format 6, scale 0.0001 m, UTM-like offsets, so the core
points carry exactly the integer coordinates of their epoch-1 points.

The surface is a sum of rotated sine x cosine octaves with amplitudes from metres down to
centimetres (wavelengths 80 m .. 0.4 m), plus Gaussian noise: rough at the scale of the
cylinder (0.5 m), still a height field, so "up" is a valid normal orientation everywhere.
"""

import argparse
import json
import os
import sys

import laspy
import numpy as np

# (amplitude m, wavelength m) per octave: metres down to centimetres.
OCTAVES = [
    (3.0, 80.0),
    (1.5, 35.0),
    (0.6, 15.0),
    (0.25, 6.0),
    (0.10, 2.5),
    (0.04, 1.0),
    (0.015, 0.4),
]
SIZE = 100.0  # side of the square area, m
OFFSET = (500000.0, 5000000.0, 0.0)
ORIGIN = (500000.0, 5000000.0, 300.0)  # lower-left corner and base height
SCALE = 0.0001
FORMAT_VERSION = 1  # bump when the generator changes, so stale data is regenerated


def surface(x, y, phases):
    """Height of the rough surface at local (x, y)."""
    z = np.zeros_like(x)
    for (amp, wl), (theta, p1, p2) in zip(OCTAVES, phases):
        k = 2.0 * np.pi / wl
        u = x * np.cos(theta) + y * np.sin(theta)
        v = -x * np.sin(theta) + y * np.cos(theta)
        z += amp * np.sin(k * u + p1) * np.cos(0.8 * k * v + p2)
    return z


def changes(x, y, bumps):
    """Planted change field (Gaussian bumps > 0, pits < 0)."""
    dz = np.zeros_like(x)
    for cx, cy, sigma, amp in bumps:
        dz += amp * np.exp(-((x - cx) ** 2 + (y - cy) ** 2) / (2.0 * sigma**2))
    return dz


def write_las(path, x, y, z):
    header = laspy.LasHeader(version="1.4", point_format=6)
    header.scales = np.array([SCALE, SCALE, SCALE])
    header.offsets = np.array(OFFSET)
    las = laspy.LasData(header)
    las.x = x
    las.y = y
    las.z = z
    las.write(path)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("outdir")
    ap.add_argument("--points", type=int, default=1_000_000, help="points per epoch")
    ap.add_argument("--cores", type=int, default=100_000, help="core points")
    ap.add_argument("--core-layout", choices=["grid", "epoch1"], default="grid")
    ap.add_argument("--noise", type=float, default=0.007, help="noise sigma, m")
    ap.add_argument("--seed", type=int, default=20241121)
    args = ap.parse_args()

    os.makedirs(args.outdir, exist_ok=True)
    stamp_path = os.path.join(args.outdir, "data.json")
    params = {
        "format_version": FORMAT_VERSION,
        "points": args.points,
        "cores": args.cores,
        "core_layout": args.core_layout,
        "noise": args.noise,
        "seed": args.seed,
    }
    names = ["before.las", "after.las", "cores.las"]
    if os.path.exists(stamp_path) and all(
        os.path.exists(os.path.join(args.outdir, n)) for n in names
    ):
        with open(stamp_path) as f:
            if json.load(f).get("params") == params:
                print(f"data: reusing {args.outdir}", file=sys.stderr)
                return

    rng = np.random.default_rng(args.seed)
    phases = [
        (rng.uniform(0, np.pi), rng.uniform(0, 2 * np.pi), rng.uniform(0, 2 * np.pi))
        for _ in OCTAVES
    ]
    # Planted changes: 8 bumps/pits, amplitude 0.2-1 m, away from the border.
    bumps = []
    for i in range(8):
        amp = rng.uniform(0.2, 1.0) * (1 if i % 2 == 0 else -1)
        bumps.append(
            (
                float(rng.uniform(15, SIZE - 15)),
                float(rng.uniform(15, SIZE - 15)),
                float(rng.uniform(1.5, 4.0)),
                float(amp),
            )
        )

    def epoch(with_changes):
        x = rng.uniform(0, SIZE, args.points)
        y = rng.uniform(0, SIZE, args.points)
        z = surface(x, y, phases) + rng.normal(0.0, args.noise, args.points)
        if with_changes:
            z += changes(x, y, bumps)
        return x + ORIGIN[0], y + ORIGIN[1], z + ORIGIN[2]

    x1, y1, z1 = epoch(False)
    x2, y2, z2 = epoch(True)
    sel = rng.choice(args.points, size=args.cores, replace=False)

    write_las(os.path.join(args.outdir, "before.las"), x1, y1, z1)
    write_las(os.path.join(args.outdir, "after.las"), x2, y2, z2)
    if args.core_layout == "grid":
        k = int(round(np.sqrt(args.cores)))
        g = (np.arange(k) + 0.5) * (SIZE / k)
        gx, gy = np.meshgrid(g, g)
        gx, gy = gx.ravel(), gy.ravel()
        gz = surface(gx, gy, phases)
        write_las(
            os.path.join(args.outdir, "cores.las"),
            gx + ORIGIN[0],
            gy + ORIGIN[1],
            gz + ORIGIN[2],
        )
    else:
        write_las(os.path.join(args.outdir, "cores.las"), x1[sel], y1[sel], z1[sel])
    with open(stamp_path, "w") as f:
        json.dump(
            {
                "params": params,
                "octaves": OCTAVES,
                "origin": ORIGIN,
                "bumps_local_xy_sigma_amp": bumps,
            },
            f,
            indent=1,
        )
    print(
        f"data: wrote {args.points} + {args.points} points, {args.cores} core points to {args.outdir}",
        file=sys.stderr,
    )


if __name__ == "__main__":
    main()
