"""talus.m3c2 against py4dgeo's M3C2 inside one Python process, on the same numpy arrays.

The benchmark's data (make_data.py: 2 x 1M points of a rough surface, ~100k grid core points)
read once with laspy; then ROUNDS rounds alternating the order (talus, py4dgeo | py4dgeo,
talus | ...), each call timed (wall and process CPU seconds) and its peak resident memory
measured: the kernel's high-water mark (VmHWM) reset before the call (/proc/self/clear_refs) and
read after it, less the resident size before it. py4dgeo's call counts from its Epochs' creation
(its kd-trees are built in run()) to the end of run(); talus's is the talus.m3c2 call. Prints
the figures, their ratios and the agreement of the distances. Exits 0 whatever the figures.
"""

import argparse
import os
import sys
import time


def status_kib(field):
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith(field + ":"):
                return int(line.split()[1])
    raise RuntimeError(f"no {field} in /proc/self/status")


def measured(fn):
    """fn()'s result, wall s, CPU s, peak RSS MiB, and the peak's growth over the RSS before."""
    with open("/proc/self/clear_refs", "w") as f:
        f.write("5")  # reset VmHWM to the current RSS
    rss0 = status_kib("VmRSS")
    c0, t0 = time.process_time(), time.perf_counter()
    out = fn()
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    hwm = status_kib("VmHWM")
    return out, wall, cpu, hwm / 1024, (hwm - rss0) / 1024


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("work", help="folder of make_data.py's before.las, after.las, cores.las")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--threads", type=int, default=os.cpu_count())
    ap.add_argument("--normal-radius", type=float, default=1.0)
    ap.add_argument("--cyl-radius", type=float, default=0.5)
    ap.add_argument("--cyl-halflen", type=float, default=3.0)
    args = ap.parse_args()
    # py4dgeo's OpenMP reads it at import.
    os.environ["OMP_NUM_THREADS"] = str(args.threads)

    import laspy
    import numpy as np
    import py4dgeo

    import talus

    py4dgeo.set_py4dgeo_logfile(os.path.join(args.work, "py4dgeo-inprocess.log"))

    def xyz(name):
        las = laspy.read(os.path.join(args.work, name))
        return np.column_stack([las.x, las.y, las.z])

    e1, e2, cores = xyz("before.las"), xyz("after.las"), xyz("cores.las")
    print(
        f"data: {len(e1)} + {len(e2)} points, {len(cores)} core points; talus {talus.__version__}, "
        f"py4dgeo {py4dgeo.__version__}, numpy {np.__version__}; {args.threads} threads each"
    )

    def run_py4dgeo():
        ep1, ep2 = py4dgeo.Epoch(e1), py4dgeo.Epoch(e2)
        m = py4dgeo.M3C2(
            epochs=(ep1, ep2),
            corepoints=cores,
            normal_radii=(args.normal_radius,),
            cyl_radius=args.cyl_radius,
            max_distance=args.cyl_halflen,
            orientation_vector=np.array([0.0, 0.0, 1.0]),
            cloud_for_normals=ep1,
        )
        d, u = m.run()
        return d, u, m.corepoint_normals

    def run_talus():
        return talus.m3c2(
            e1,
            e2,
            cores,
            normal_radii=(args.normal_radius,),
            cyl_radius=args.cyl_radius,
            max_distance=args.cyl_halflen,
            threads=args.threads,
            progress=False,
        )

    runs = {"talus": [], "py4dgeo": []}
    last = {}
    print(f"{'round':>5} {'tool':8} {'wall s':>8} {'cpu s':>8} {'peak RSS MiB':>13} {'peak growth MiB':>16}")
    for r in range(1, args.rounds + 1):
        order = ("talus", "py4dgeo") if r % 2 else ("py4dgeo", "talus")
        for tool in order:
            out, wall, cpu, hwm, grow = measured(run_talus if tool == "talus" else run_py4dgeo)
            runs[tool].append((wall, cpu, hwm, grow))
            last[tool] = out
            print(f"{r:>5} {tool:8} {wall:8.2f} {cpu:8.2f} {hwm:13.1f} {grow:16.1f}")
            del out

    def med(tool, k):
        return float(np.median([x[k] for x in runs[tool]]))

    print("\n== summary (medians over rounds; peak growth = the call's high-water mark less the RSS before it)")
    print(f"{'':22} {'talus':>10} {'py4dgeo':>10} {'py4dgeo/talus':>14}")
    for k, label in ((0, "wall s"), (1, "CPU s"), (3, "peak growth MiB")):
        t, p = med("talus", k), med("py4dgeo", k)
        print(f"{label:22} {t:10.2f} {p:10.2f} {p / t:14.2f}")
    t_best = min(x[0] for x in runs["talus"])
    p_best = min(x[0] for x in runs["py4dgeo"])
    print(f"{'wall s, best':22} {t_best:10.2f} {p_best:10.2f} {p_best / t_best:14.2f}")

    res = last["talus"]
    d_p, u_p, n_p = last["py4dgeo"]
    d_t = res.distances
    both = np.isfinite(d_t) & np.isfinite(d_p)
    dd = np.abs(d_t - d_p)[both] * 1000.0
    same = (res.num_samples1 == u_p["num_samples1"]) & (res.num_samples2 == u_p["num_samples2"])
    cos = np.abs(np.einsum("ij,ij->i", res.normals, n_p))
    ok = np.isfinite(cos)
    ang = np.degrees(np.arccos(np.clip(cos[ok], 0.0, 1.0)))
    print("\n== agreement (last round)")
    print(
        f"distances: talus {int(np.isfinite(d_t).sum())}, py4dgeo {int(np.isfinite(d_p).sum())}, "
        f"both {int(both.sum())}; |delta d| mm median {np.median(dd):.2e}, "
        f"p99 {np.percentile(dd, 99):.2e}, max {dd.max():.2e}"
    )
    print(f"identical counts (both epochs): {100.0 * same.mean():.3f} %")
    print(f"normals: angle median {np.median(ang):.2e} deg, max {ang.max():.2e} deg")
    return 0


if __name__ == "__main__":
    sys.exit(main())
