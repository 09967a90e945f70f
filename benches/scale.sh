#!/usr/bin/env bash
# Scale benchmark (issue "Out-of-core tiles"): `talus synth large` at several sizes per epoch
# (LAZ), then `talus compare` with default parameters, each under /usr/bin/time -v. Reports wall
# time per stage, peak RSS, and the events found against the planted truth.
#
#   bash benches/scale.sh                      # sizes 10M 40M 120M
#   SIZES="2000000" bash benches/scale.sh      # a quick run
#   SCALE_WORK=/path bash benches/scale.sh     # where the data goes (default: bench-work/scale)
#
# Goals on a 2-core machine: 120M per epoch end to end ≤ 5 minutes (issue 13), peak RSS ≤ 2 GiB
# with the default budget, every planted event found with |V − V_true| ≤ 2 %.
set -euo pipefail
repo="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$repo"
SIZES="${SIZES:-10000000 40000000 120000000}"
WORK="${SCALE_WORK:-$repo/bench-work/scale}"
mkdir -p "$WORK"
. "$repo/benches/common.sh" scale.sh

for n in $SIZES; do
  d="$WORK/large-$n"
  if [ ! -f "$d/truth.json" ]; then
    echo "scale.sh: synth large --points $n" >&2
    /usr/bin/time -v "$talus" synth large --points "$n" --out "$d" 2> "$d.synth.time" >/dev/null \
      || { cat "$d.synth.time" >&2; exit 1; }
  fi
  echo "scale.sh: compare at $n points per epoch" >&2
  /usr/bin/time -v "$talus" compare "$d/before.laz" "$d/after.laz" --out "$d/res" --force \
    2> "$d.compare.time" || { cat "$d.compare.time" >&2; exit 1; }
done

python3 - "$WORK" $SIZES <<'PY'
import json, math, re, sys
work, sizes = sys.argv[1], [int(s) for s in sys.argv[2:]]

def timev(path):
    t = open(path).read()
    wall = re.search(r"Elapsed \(wall clock\) time \(h:mm:ss or m:ss\): (\S+)", t).group(1)
    parts = [float(p) for p in wall.split(":")]
    secs = sum(p * 60 ** i for i, p in enumerate(reversed(parts)))
    rss = int(re.search(r"Maximum resident set size \(kbytes\): (\d+)", t).group(1)) / 1024
    return secs, rss

rows = []
for n in sizes:
    d = f"{work}/large-{n}"
    s = json.load(open(f"{d}/res/summary.json"))
    truth = json.load(open(f"{d}/truth.json"))["events"]
    found = json.load(open(f"{d}/res/events.geojson"))["features"]
    wall, rss = timev(f"{d}.compare.time")
    swall, srss = timev(f"{d}.synth.time") if __import__("os").path.exists(f"{d}.synth.time") else (float("nan"), float("nan"))
    used, matched, errs = set(), 0, []
    for t in truth:
        best, bd = None, 1e18
        for i, f in enumerate(found):
            p = f["properties"]
            if i in used or p["kind"] != t["kind"]:
                continue
            c = f["geometry"]["coordinates"]
            dd = math.dist(c[:2], t["centre"][:2])
            if dd < bd:
                best, bd = i, dd
        if best is not None and bd < 3 * max(t.get("radius_m", 3.0), 1.0):
            used.add(best)
            matched += 1
            v = found[best]["properties"]["volume_m3"]
            errs.append(100 * abs(v - t["volume_m3"]) / abs(t["volume_m3"]) if v is not None else float("inf"))
    extra = [f["properties"]["volume_m3"] for i, f in enumerate(found) if i not in used]
    # Wall time per stage from the run's stage lines ("talus: <stage>: <n> <unit> in <s> s"),
    # which the time -v file holds with the rest of stderr.
    stages = {}
    for line in open(f"{d}.compare.time"):
        m = re.match(r"talus: (.+?): \d+ .+? in ([\d.]+) s", line)
        if m:
            stages[m.group(1)] = stages.get(m.group(1), 0.0) + float(m.group(2))
    rows.append((n, wall, rss, stages, s["tiles"], s["core_points"], len(truth), matched, errs, extra, swall, srss))

print()
print("| points/epoch | synth s | compare wall s | peak RSS MiB | tiles | core points | events found / planted | worst |dV| % | within 2 % | extra events |")
print("|---|---|---|---|---|---|---|---|---|---|")
for n, wall, rss, st, tiles, cores, nt, m, errs, extra, sw, _ in rows:
    worst = max(errs) if errs else float("nan")
    ok = sum(e <= 2.0 for e in errs)
    print(f"| {n:,} | {sw:.0f} | {wall:.0f} | {rss:.0f} | {tiles} | {cores:,} | {m} / {nt} | {worst:.2f} | {ok} / {nt} | {len(extra)} |")
print()
print("stage seconds:")
names = list(rows[0][3].keys())
print("| points/epoch | " + " | ".join(names) + " |")
print("|---|" + "---|" * len(names))
for r in rows:
    print(f"| {r[0]:,} | " + " | ".join(f"{r[3].get(k, float('nan')):.1f}" for k in names) + " |")
if len(rows) > 1:
    a, b = rows[0], rows[-1]
    print()
    print(f"growth {a[0]:,} → {b[0]:,} points ({b[0]/a[0]:.1f}×): wall ×{b[1]/a[1]:.2f}, peak RSS ×{b[2]/a[2]:.2f}")
big = rows[-1]
print()
print(f"goals at {big[0]:,}: end to end ≤ 5 min: {'met' if big[1] <= 300 else 'NOT met'} ({big[1]/60:.1f} min); "
      f"peak RSS ≤ 2 GiB: {'met' if big[2] <= 2048 else 'NOT met'} ({big[2]:.0f} MiB); "
      f"every event within 2 %: {'met' if big[7] == big[6] and all(e <= 2 for e in big[8]) else 'NOT met'}")
PY
