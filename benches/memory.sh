#!/usr/bin/env bash
# Memory benchmark (issue "`--memory` as a hard bound"): `talus compare` under /usr/bin/time -v at
# several budgets on a 5.2M-point-per-epoch cliff (LAZ), and optionally at 1 GiB on the 120M
# pair of benches/scale.sh. Prints, per budget, each stage's peak resident memory (sampled by
# talus while the stage's units run) and the whole process's peak (the kernel's, from time -v),
# against the bound of 1.1 × the budget.
#
#   bash benches/memory.sh                          # 256MiB 1GiB 2GiB on the 5.2M cliff
#   BUDGETS="300MiB" bash benches/memory.sh         # one budget
#   BIG=1 bash benches/memory.sh                    # also 1 GiB on large-120000000 (scale.sh's)
#   MEMORY_WORK=/path bash benches/memory.sh        # where the data goes (default bench-work/memory)
set -euo pipefail
repo="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$repo"
BUDGETS="${BUDGETS:-256MiB 1GiB 2GiB}"
WORK="${MEMORY_WORK:-$repo/bench-work/memory}"
SCALE="${SCALE_WORK:-$repo/bench-work/scale}"
mkdir -p "$WORK"
if [ ! -x /usr/bin/time ]; then
  echo "memory.sh: installing GNU time" >&2
  DEBIAN_FRONTEND=noninteractive apt-get install -y -q time >/dev/null
fi
cargo build --release --quiet
talus="$repo/target/release/talus"

scene="$WORK/cliff-5200000"
if [ ! -f "$scene/truth.json" ]; then
  echo "memory.sh: synth cliff --points 5200000" >&2
  "$talus" synth cliff --points 5200000 --out "$scene" >/dev/null
fi

runs=()
for b in $BUDGETS; do
  echo "memory.sh: compare on the cliff at --memory $b" >&2
  /usr/bin/time -v "$talus" compare "$scene/before.laz" "$scene/after.laz" --out "$WORK/res-$b" \
    --force --memory "$b" 2> "$WORK/cliff-$b.time" || { cat "$WORK/cliff-$b.time" >&2; exit 1; }
  runs+=("cliff-5.2M $b $WORK/cliff-$b.time")
done
if [ "${BIG:-0}" = 1 ]; then
  d="$SCALE/large-120000000"
  [ -f "$d/truth.json" ] || { echo "memory.sh: $d missing: run SIZES=120000000 bash benches/scale.sh" >&2; exit 1; }
  echo "memory.sh: compare on the 120M pair at --memory 1GiB" >&2
  /usr/bin/time -v "$talus" compare "$d/before.laz" "$d/after.laz" --out "$WORK/res-120M" \
    --force --memory 1GiB 2> "$WORK/large-1GiB.time" || { cat "$WORK/large-1GiB.time" >&2; exit 1; }
  runs+=("large-120M 1GiB $WORK/large-1GiB.time")
fi

python3 - "${runs[@]}" <<'PY'
import re, sys
units = {"MiB": 2**20, "GiB": 2**30}
stages = ["tiling", "normals and M3C2", "merging tiles", "stable ground", "events", "m3c2.laz", "volumes", "outputs"]
print(f"| scene | --memory | " + " | ".join(stages) + " | process peak | peak / budget | wall |")
print("|---|---|" + "---|" * len(stages) + "---|---|---|")
worst = 0.0
for run in sys.argv[1:]:
    scene, budget, path = run.split(" ")
    t = open(path).read()
    b = float(re.match(r"([\d.]+)", budget).group(1)) * units[budget[-3:]] / 2**20
    peaks = []
    for s in stages:
        m = re.search(rf"talus: (?:pass \d: )?{re.escape(s)}: .*?peak (\d+) MiB", t)
        peaks.append(m.group(1) if m else "–")
    rss = int(re.search(r"Maximum resident set size \(kbytes\): (\d+)", t).group(1)) / 1024
    wall = re.search(r"Elapsed \(wall clock\) time \(h:mm:ss or m:ss\): (\S+)", t).group(1)
    worst = max(worst, rss / b)
    print(f"| {scene} | {budget} | " + " | ".join(peaks) + f" | {rss:.0f} MiB | {rss / b:.2f} | {wall} |")
print(f"\nworst peak / budget: {worst:.2f} (bound: 1.10)")
sys.exit(0 if worst <= 1.10 else 1)
PY
