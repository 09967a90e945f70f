"""Report of the talus vs py4dgeo M3C2 benchmark: speed, memory and agreement.

Reads
  TIMES/{talus,py4dgeo}_<round>.time   `/usr/bin/time -v` output of each timed process
  TIMES/{talus,py4dgeo}_<round>.load   /proc/loadavg just before that process started
  TALUS_OUT/m3c2.laz                   talus's core points with the PDAL-named extra dimensions
  PY_OUT/{distances,uncertainties,normals}.npy   what run_py4dgeo.py saved
  CORES                                the core-point file both tools were given
and prints the figures, then a summary table with the goals marked met / not met.
It always exits 0 when the inputs are readable: a benchmark reports, it does not judge.
"""

import argparse
import glob
import json
import os
import re
import sys

import laspy
import numpy as np

MIB = 1024.0 * 1024.0


def parse_time_v(path):
    """Wall seconds, user + system CPU seconds, max RSS bytes and exit status from time -v."""
    text = open(path).read()

    def field(label):
        m = re.search(r"^\s*" + re.escape(label) + r":\s*(.+)$", text, re.M)
        if not m:
            raise ValueError(f"{path}: no '{label}' line")
        return m.group(1).strip()

    parts = [float(p) for p in field("Elapsed (wall clock) time (h:mm:ss or m:ss)").split(":")]
    wall = 0.0
    for p in parts:
        wall = wall * 60.0 + p
    cpu = float(field("User time (seconds)")) + float(field("System time (seconds)"))
    rss = int(field("Maximum resident set size (kbytes)")) * 1024
    status = int(field("Exit status"))
    return {"wall": wall, "cpu": cpu, "rss": rss, "status": status}


def runs(times_dir, tool):
    out = []
    for path in sorted(glob.glob(os.path.join(times_dir, f"{tool}_*.time"))):
        r = parse_time_v(path)
        load_path = path[: -len(".time")] + ".load"
        r["load"] = (
            float(open(load_path).read().split()[0]) if os.path.exists(load_path) else float("nan")
        )
        out.append(r)
    return out


def match_order(talus_xyz, cores_xyz, tol):
    """Index into talus rows for each core point (talus should keep the file's order).

    `tol`: half the output's coordinate scale (talus rounds m3c2.laz to its own scale)."""
    if len(talus_xyz) == len(cores_xyz):
        off = np.abs(talus_xyz - cores_xyz).max()
        if off <= tol:
            return np.arange(len(cores_xyz)), off, True
    # Fallback: match on coordinates rounded to the output's scale.
    key = lambda a: [tuple(r) for r in np.round(a / (2 * tol)).astype(np.int64)]  # noqa: E731
    where = {k: i for i, k in enumerate(key(talus_xyz))}
    idx = np.array([where.get(k, -1) for k in key(cores_xyz)])
    return idx, float("nan"), False


def reference_check(before, after, cores_xyz, normals, r, h, sample, seed=7):
    """Brute-force cylinders for a sample of core points, two ways, to explain disagreements.

    exact:   SPEC.md §1 / Lague et al. 2013: |t| <= h and radial distance <= r, each point once.
    py4dgeo: an emulation of py4dgeo 1.2's cylinder_workingset_finder (lib/distances.cpp): the
             axis cut into N = ceil(h / r) segments, a point accepted by every segment whose
             midpoint plane is strictly closer than h / N, computed in absolute coordinates in
             the same order of operations (so the same rounding).
    `normals`: py4dgeo's (independent of talus). Returns per sampled core point the index, both
    distances and both epoch-1/epoch-2 counts.
    """
    from scipy.spatial import cKDTree

    rng = np.random.default_rng(seed)
    pick = np.sort(rng.choice(len(cores_xyz), size=min(sample, len(cores_xyz)), replace=False))
    ball = np.sqrt(r * r + h * h) * (1.0 + 1e-9)
    nseg = int(np.ceil(h / r)) if h > r else 1
    length = h if h > r else r
    out = {"index": pick}
    for name, path in (("1", before), ("2", after)):
        las = laspy.read(path)
        pts = np.column_stack([las.x, las.y, las.z])
        tree = cKDTree(pts)
        hits = tree.query_ball_point(cores_xyz[pick], ball)
        ex_n, ex_t, py_n, py_t = [], [], [], []
        for k, i in enumerate(pick):
            q, n = cores_xyz[i], normals[i]
            sub = pts[np.asarray(hits[k], dtype=np.int64)]
            v = sub - q
            t = v @ n
            rad2 = np.einsum("ij,ij->i", v, v) - t * t
            inside = (np.abs(t) <= h) & (rad2 <= r * r)
            ex_n.append(int(inside.sum()))
            ex_t.append(float(t[inside].mean()) if inside.any() else np.nan)
            acc = []
            for s in range(nseg):
                qp = q + ((2 * s + 1 - nseg) / nseg) * length * n
                tm = sub - qp
                plane = tm @ n
                axis2 = np.sum((tm - plane[:, None] * n) ** 2, axis=1)
                acc.append(sub[(axis2 <= r * r) & (np.abs(plane) < length / nseg)])
            acc = np.concatenate(acc)
            py_n.append(len(acc))
            py_t.append(float(acc.mean(axis=0) @ n) if len(acc) else np.nan)
        out["exact_n" + name], out["exact_t" + name] = np.array(ex_n), np.array(ex_t)
        out["py_n" + name], out["py_t" + name] = np.array(py_n), np.array(py_t)
    out["exact_d"] = out["exact_t2"] - out["exact_t1"]
    out["py_d"] = out["py_t2"] - out["py_t1"]
    return out


def pct(a, q):
    return float(np.percentile(a, q)) if len(a) else float("nan")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--times", required=True)
    ap.add_argument("--talus-out", required=True)
    ap.add_argument("--py-out", required=True)
    ap.add_argument("--cores", required=True)
    ap.add_argument("--cyl-radius", type=float, default=0.5)
    ap.add_argument("--cyl-halflen", type=float, default=3.0)
    ap.add_argument("--before", help="epoch 1 (for the brute-force reference check)")
    ap.add_argument("--after", help="epoch 2 (for the brute-force reference check)")
    ap.add_argument("--reference-sample", type=int, default=2000, help="0 = skip the check")
    ap.add_argument("--goal-speedup", type=float, default=3.0)
    ap.add_argument("--goal-median-mm", type=float, default=0.1)
    args = ap.parse_args()

    t_runs, p_runs = runs(args.times, "talus"), runs(args.times, "py4dgeo")
    if not t_runs or not p_runs:
        print("compare: no timed runs found in " + args.times, file=sys.stderr)
        return 1
    failed = [r for r in t_runs + p_runs if r["status"] != 0]

    def med(rs, k):
        return float(np.median([r[k] for r in rs]))

    t_wall, p_wall = med(t_runs, "wall"), med(p_runs, "wall")
    t_cpu, p_cpu = med(t_runs, "cpu"), med(p_runs, "cpu")
    t_rss, p_rss = max(r["rss"] for r in t_runs), max(r["rss"] for r in p_runs)

    print(f"== timed runs (whole processes, alternating; {len(t_runs)} + {len(p_runs)})")
    print(f"{'tool':8} {'round':>5} {'wall s':>8} {'cpu s':>8} {'cpu %':>6} {'RSS MiB':>8} {'load1':>6}")
    for tool, rs in (("talus", t_runs), ("py4dgeo", p_runs)):
        for i, r in enumerate(rs, 1):
            print(
                f"{tool:8} {i:>5} {r['wall']:8.2f} {r['cpu']:8.2f} "
                f"{100 * r['cpu'] / max(r['wall'], 1e-9):6.0f} {r['rss'] / MIB:8.1f} {r['load']:6.2f}"
            )
    phases = os.path.join(args.py_out, "phases.json")
    if os.path.exists(phases):
        ph = json.load(open(phases))
        print(
            f"py4dgeo {ph['py4dgeo_version']} phases (last run, wall s): import {ph['import']:.2f}, "
            f"read {ph['read']:.2f}, M3C2 {ph['m3c2']:.2f}, save {ph['save']:.2f}; "
            f"OpenMP threads {ph['threads']}"
        )
    summary = os.path.join(args.talus_out, "summary.json")
    if os.path.exists(summary):
        s = json.load(open(summary))
        st = ", ".join(f"{x['stage']} {x['seconds']:.2f}" for x in s.get("stages", []))
        thr = s.get("parameters", {}).get("threads", {}).get("value", "?")
        print(f"talus stages (last run, wall s): {st}; threads {thr}; tiles {s.get('tiles', '?')}")
    if failed:
        print(f"WARNING: {len(failed)} timed process(es) exited non-zero")
    ncpu = os.cpu_count() or 1
    loads = [r["load"] for r in t_runs + p_runs if np.isfinite(r["load"])]
    if loads and max(loads) > 0.5 * ncpu:
        print(
            f"WARNING: the machine was busy (1-min load up to {max(loads):.1f} on {ncpu} cores "
            "before a timed run): wall times are inflated by other processes; CPU seconds "
            "(user + system) are the steadier figure"
        )

    # ---- agreement
    cores = laspy.read(args.cores)
    cores_xyz = np.column_stack([cores.x, cores.y, cores.z])
    tl = laspy.read(os.path.join(args.talus_out, "m3c2.laz"))
    t_xyz = np.column_stack([tl.x, tl.y, tl.z])
    tol = 0.5 * float(np.max(tl.header.scales)) * (1 + 1e-6)
    idx, off, in_order = match_order(t_xyz, cores_xyz, tol)
    ok = idx >= 0
    n = len(cores_xyz)

    def tcol(name, dtype=float):
        out = np.full(n, np.nan if dtype is float else -1, dtype=dtype)
        out[ok] = np.asarray(tl[name], dtype=dtype)[idx[ok]]
        return out

    d_t = tcol("m3c2_distance")
    c1_t, c2_t = tcol("m3c2_count1", np.int64), tcol("m3c2_count2", np.int64)
    n_t = np.column_stack([tcol("normal_x"), tcol("normal_y"), tcol("normal_z")])

    d_p = np.load(os.path.join(args.py_out, "distances.npy"))
    unc = np.load(os.path.join(args.py_out, "uncertainties.npy"))
    c1_p = np.asarray(unc["num_samples1"], dtype=np.int64)
    c2_p = np.asarray(unc["num_samples2"], dtype=np.int64)
    n_p = np.load(os.path.join(args.py_out, "normals.npy"))
    if len(d_p) != n:
        print(f"compare: py4dgeo gave {len(d_p)} distances for {n} core points", file=sys.stderr)
        return 1

    print("\n== agreement (per core point)")
    if in_order:
        print(
            f"talus kept the core-point order (max coordinate offset {off * 1000:.3f} mm; "
            f"m3c2.laz scale {np.max(tl.header.scales):g} m, core file scale "
            f"{np.max(cores.header.scales):g} m)"
        )
    else:
        print(f"talus did NOT keep the core-point order: matched {ok.sum()} of {n} by coordinates")
    if args.cyl_halflen <= args.cyl_radius:
        print(
            "NOTE: cyl_halflen <= cyl_radius: py4dgeo then uses cyl_radius as the half-length, "
            "so its cylinders are longer than talus's"
        )
    fin_t, fin_p = np.isfinite(d_t), np.isfinite(d_p)
    both = fin_t & fin_p
    print(
        f"distances: talus {fin_t.sum()}, py4dgeo {fin_p.sum()}, both {both.sum()} of {n}; "
        f"only talus {(fin_t & ~fin_p).sum()}, only py4dgeo {(~fin_t & fin_p).sum()}"
    )
    ad = np.abs(d_t - d_p)[both] * 1000.0
    med_mm, p99_mm = float(np.median(ad)) if len(ad) else float("nan"), pct(ad, 99)
    print(
        f"|Δd| mm: median {med_mm:.4f}, p90 {pct(ad, 90):.4f}, p99 {p99_mm:.4f}, "
        f"p99.9 {pct(ad, 99.9):.4f}, max {ad.max() if len(ad) else float('nan'):.4f}"
    )
    same1, same2 = c1_t == c1_p, c2_t == c2_p
    same = same1 & same2
    print(
        f"identical counts: both epochs {100 * same.mean():.3f} % "
        f"(epoch 1 {100 * same1.mean():.3f} %, epoch 2 {100 * same2.mean():.3f} %)"
    )
    dc = np.concatenate([(c1_t - c1_p)[~same1], (c2_t - c2_p)[~same2]])
    if len(dc):
        vals, cnt = np.unique(dc, return_counts=True)
        top = sorted(zip(cnt, vals), reverse=True)[:6]
        print("count differences talus - py4dgeo (value: cylinders): " + ", ".join(f"{v:+d}: {c}" for c, v in top))
    if same.any():
        sa = (np.abs(d_t - d_p)[both & same]) * 1000.0
        print(f"|Δd| mm where counts are identical: median {np.median(sa):.6f}, max {sa.max():.6f}")
    if (~same & both).any():
        sd = (np.abs(d_t - d_p)[both & ~same]) * 1000.0
        print(f"|Δd| mm where counts differ: median {np.median(sd):.4f}, max {sd.max():.4f}")
    nt_len = np.linalg.norm(n_t, axis=1)
    fin_n = np.isfinite(nt_len) & np.all(np.isfinite(n_p), axis=1)
    dots = np.einsum("ij,ij->i", n_t[fin_n], n_p[fin_n]) / nt_len[fin_n]
    ang = np.degrees(np.arccos(np.clip(np.abs(dots), 0.0, 1.0)))
    print(
        f"normals: angle talus vs py4dgeo median {np.median(ang):.2e}°, p99 {pct(ang, 99):.2e}°, "
        f"max {ang.max():.2e}°; opposite sign {(dots < 0).sum()}; "
        f"talus normals with n_z < 0: {(n_t[fin_n][:, 2] < 0).sum()}"
    )
    worst = np.argsort(-np.where(both, np.abs(d_t - d_p), -1.0))[:5]
    print("largest |Δd|: core  d_talus  d_py4dgeo (m)  counts talus / py4dgeo  normal angle °")
    for i in worst:
        if not both[i]:
            continue
        a = np.degrees(np.arccos(min(1.0, abs(float(np.dot(n_t[i], n_p[i])) / nt_len[i]))))
        print(
            f"  {i:7d} {d_t[i]:+.5f} {d_p[i]:+.5f}  {c1_t[i]}/{c2_t[i]} vs {c1_p[i]}/{c2_p[i]}  {a:.2e}"
        )

    ref_t_med = ref_t_max = float("nan")
    if args.before and args.after and args.reference_sample > 0:
        ref = reference_check(
            args.before, args.after, cores_xyz, n_p, args.cyl_radius, args.cyl_halflen,
            args.reference_sample,
        )
        k = ref["index"]
        m = len(k)
        print(f"\n== brute-force reference on {m} sampled core points (py4dgeo's normals)")
        t_ok = (c1_t[k] == ref["exact_n1"]) & (c2_t[k] == ref["exact_n2"])
        p_ok = (c1_p[k] == ref["py_n1"]) & (c2_p[k] == ref["py_n2"])
        print(
            f"talus counts = exact cylinder counts: {t_ok.sum()} of {m}; py4dgeo counts = "
            f"emulated py4dgeo segment counts: {p_ok.sum()} of {m}"
        )
        nseg = int(np.ceil(args.cyl_halflen / args.cyl_radius))
        core_twice = (ref["py_n1"] - ref["exact_n1"] == 1).sum()
        core_dropped = (ref["py_n1"] - ref["exact_n1"] == -1).sum()
        print(
            f"epoch 1, py4dgeo vs exact: one point more (the core point itself, t = 0, lies on "
            f"the boundary of two of py4dgeo's {nseg} axis segments and is counted by both) "
            f"{core_twice}, one point fewer (counted by neither) {core_dropped}, other "
            f"{m - core_twice - core_dropped}"
        )
        e_t = np.abs(d_t[k] - ref["exact_d"]) * 1000.0
        e_p = np.abs(d_p[k] - ref["exact_d"]) * 1000.0
        e_pe = np.abs(d_p[k] - ref["py_d"]) * 1000.0
        ref_t_med, ref_t_max = float(np.nanmedian(e_t)), float(np.nanmax(e_t))
        print(f"|d_talus - d_exact| mm:          median {ref_t_med:.2e}, max {ref_t_max:.2e}")
        print(f"|d_py4dgeo - d_exact| mm:        median {np.nanmedian(e_p):.4f}, max {np.nanmax(e_p):.4f}")
        print(f"|d_py4dgeo - d_py4dgeo_emul| mm: median {np.nanmedian(e_pe):.2e}, max {np.nanmax(e_pe):.2e}")

    # ---- summary
    speed = p_wall / t_wall
    cpu_ratio = p_cpu / t_cpu
    mem = p_rss / t_rss

    def mark(good):
        return "met" if good else "NOT met"

    print("\n== summary")
    print(f"{'':28} {'talus':>10} {'py4dgeo':>10} {'py4dgeo/talus':>14}  goal")
    print(
        f"{'wall time, median (s)':28} {t_wall:10.2f} {p_wall:10.2f} {speed:14.2f}  "
        f">= {args.goal_speedup:g}x: {mark(speed >= args.goal_speedup)}"
    )
    t_best, p_best = min(r["wall"] for r in t_runs), min(r["wall"] for r in p_runs)
    print(
        f"{'wall time, best (s)':28} {t_best:10.2f} {p_best:10.2f} {p_best / t_best:14.2f}"
        "  (least disturbed by other load)"
    )
    print(f"{'CPU user+sys, median (s)':28} {t_cpu:10.2f} {p_cpu:10.2f} {cpu_ratio:14.2f}")
    print(
        f"{'peak RSS (MiB)':28} {t_rss / MIB:10.1f} {p_rss / MIB:10.1f} {mem:14.2f}  "
        f"talus below py4dgeo: {mark(t_rss < p_rss)}"
    )
    print(f"{'points with a distance':28} {fin_t.sum():10d} {fin_p.sum():10d} {'both ' + str(both.sum()):>14}")
    print(
        f"{'median |Δd| (mm)':28} {med_mm:21.4f} {'':14}  <= {args.goal_median_mm:g} mm: "
        f"{mark(med_mm <= args.goal_median_mm)}"
    )
    print(f"{'p99 |Δd| (mm)':28} {p99_mm:21.4f}")
    print(f"{'identical counts (%)':28} {100 * same.mean():21.3f}")
    if np.isfinite(ref_t_med):
        print(
            f"{'talus vs exact |Δd| (mm)':28} {'median %.1e, max %.1e' % (ref_t_med, ref_t_max):>21}"
            f"  (brute-force reference, {args.reference_sample} sampled core points)"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
