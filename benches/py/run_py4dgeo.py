"""M3C2 with py4dgeo on the benchmark data: the counterpart of one `talus compare` run.

Reads both epochs and the core points from LAS (py4dgeo.read_from_las), runs py4dgeo.M3C2
with the benchmark's parameters and saves, in OUTDIR:
  distances.npy      float64, one per core point, in the core-point file's order
  uncertainties.npy  py4dgeo's structured array (lodetection, spread1, num_samples1, ...)
  normals.npy        the core-point normals py4dgeo used (n x 3)
  phases.json        wall seconds of the phases inside the process (import, read, m3c2, save)

Matching talus's definition (verified in py4dgeo 1.2 sources, m3c2.py and lib/directions.cpp):
- normals are computed on epochs[0] (= before.las) when cloud_for_normals is None: we pass
  epoch 1 explicitly anyway, so a change of default cannot silently change the comparison;
- the normal's sign is flipped so that n . orientation_vector >= 0; the default vector is
  (0, 0, 1), i.e. talus's `--orientation up`; passed explicitly for the same reason;
- the cylinder extends max_distance on both sides of the core point (half-length), radius
  cyl_radius; distance = n . (mean2 - mean1), as talus's t2 - t1.
Differences that remain by design: py4dgeo's spread is the sample standard deviation (n - 1),
talus's the population one; py4dgeo accepts a point in a cylinder segment with a strict
|t - t_mid| < L/N, so points exactly on a segment boundary are dropped or, after rounding,
counted by two segments.
"""

import time

T0 = time.perf_counter()

import argparse  # noqa: E402
import json  # noqa: E402
import os  # noqa: E402

import numpy as np  # noqa: E402
import py4dgeo  # noqa: E402


def main():
    t_import = time.perf_counter() - T0
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("before")
    ap.add_argument("after")
    ap.add_argument("cores")
    ap.add_argument("outdir")
    ap.add_argument("--normal-radius", type=float, default=1.0)
    ap.add_argument("--cyl-radius", type=float, default=0.5)
    ap.add_argument("--cyl-halflen", type=float, default=3.0)
    args = ap.parse_args()
    os.makedirs(args.outdir, exist_ok=True)
    # py4dgeo appends its log to ./py4dgeo.log by default; keep it with the outputs.
    py4dgeo.set_py4dgeo_logfile(os.path.join(args.outdir, "py4dgeo.log"))

    t = time.perf_counter()
    epoch1, epoch2 = py4dgeo.read_from_las(args.before, args.after)
    corepoints = py4dgeo.read_from_las(args.cores).cloud
    t_read = time.perf_counter() - t

    t = time.perf_counter()
    m3c2 = py4dgeo.M3C2(
        epochs=(epoch1, epoch2),
        corepoints=corepoints,
        normal_radii=(args.normal_radius,),
        orientation_vector=np.array([0.0, 0.0, 1.0]),
        cloud_for_normals=epoch1,
        cyl_radius=args.cyl_radius,
        max_distance=args.cyl_halflen,
    )
    distances, uncertainties = m3c2.run()
    t_m3c2 = time.perf_counter() - t

    t = time.perf_counter()
    np.save(os.path.join(args.outdir, "distances.npy"), distances)
    np.save(os.path.join(args.outdir, "uncertainties.npy"), uncertainties)
    np.save(os.path.join(args.outdir, "normals.npy"), m3c2.corepoint_normals)
    t_save = time.perf_counter() - t

    with open(os.path.join(args.outdir, "phases.json"), "w") as f:
        json.dump(
            {
                "py4dgeo_version": py4dgeo.__version__,
                "threads": py4dgeo.get_num_threads(),
                "import": t_import,
                "read": t_read,
                "m3c2": t_m3c2,
                "save": t_save,
            },
            f,
            indent=1,
        )


if __name__ == "__main__":
    main()
