#!/usr/bin/env bash
# Campaign benchmark (issue "Campaigns"): one `talus campaign` of 4 synthetic surveys against the
# same 3 consecutive pairs run as 3 separate `talus compare`s, each process under
# /usr/bin/time -v: wall time, CPU time and peak RSS, and the ratios. A campaign tiles each survey
# once (a compare tiles both of its surveys: the middle two surveys are tiled twice over the three
# compares) and derives its parameters and core points once.
#
#   bash benches/campaign.sh                          # 4 surveys of 10M points
#   POINTS=1000000 bash benches/campaign.sh           # a quick run
#   CAMPAIGN_WORK=/path bash benches/campaign.sh      # where the data go (default: bench-work/campaign)
#
# Needs cargo and GNU time (installed with apt-get when missing and running as root). Disk: the
# surveys (about 45 MB per 10M points) and the runs' stores (a few GB at 10M points); the data are
# kept and reused, the runs are redone (--force). The script exits 0 whatever the figures are.
set -euo pipefail
repo="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$repo"
POINTS="${POINTS:-10000000}"
EPOCHS=4
WORK="${CAMPAIGN_WORK:-$repo/bench-work/campaign}"
mkdir -p "$WORK"
. "$repo/benches/common.sh" campaign.sh

data="$WORK/data-$POINTS"
if [ ! -f "$data/truth.json" ]; then
  echo "campaign.sh: synth campaign --epochs $EPOCHS --points $POINTS" >&2
  "$talus" synth campaign --epochs "$EPOCHS" --points "$POINTS" --out "$data" >/dev/null
fi
mapfile -t surveys < <(ls "$data"/survey_*.laz | sort)
[ "${#surveys[@]}" -eq "$EPOCHS" ] || { echo "campaign.sh: expected $EPOCHS surveys in $data" >&2; exit 1; }

load() { cut -d' ' -f1 /proc/loadavg; }

echo "campaign.sh: talus campaign of $EPOCHS surveys (load $(load))" >&2
echo "$(load)" > "$WORK/campaign.load"
/usr/bin/time -v "$talus" campaign "${surveys[@]}" --out "$WORK/campaign" --force \
  2> "$WORK/campaign.time" >/dev/null || { cat "$WORK/campaign.time" >&2; exit 1; }
for k in $(seq 1 $((EPOCHS - 1))); do
  b="${surveys[$((k - 1))]}"
  a="${surveys[$k]}"
  echo "campaign.sh: talus compare $(basename "$b") $(basename "$a") (load $(load))" >&2
  echo "$(load)" > "$WORK/compare-$k.load"
  /usr/bin/time -v "$talus" compare "$b" "$a" --out "$WORK/compare-$k" --force \
    2> "$WORK/compare-$k.time" >/dev/null || { cat "$WORK/compare-$k.time" >&2; exit 1; }
done

python3 - "$WORK" "$EPOCHS" "$POINTS" <<'PY'
import json, os, re, sys
work, epochs, points = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])

def timev(name):
    t = open(f"{work}/{name}.time").read()
    wall = re.search(r"Elapsed \(wall clock\) time \(h:mm:ss or m:ss\): (\S+)", t).group(1)
    secs = sum(float(p) * 60 ** i for i, p in enumerate(reversed(wall.split(":"))))
    cpu = sum(float(re.search(rf"{k} time \(seconds\): ([\d.]+)", t).group(1)) for k in ("User", "System"))
    rss = int(re.search(r"Maximum resident set size \(kbytes\): (\d+)", t).group(1)) / 1024
    load = open(f"{work}/{name}.load").read().strip()
    return secs, cpu, rss, load

camp = timev("campaign")
comps = [timev(f"compare-{k}") for k in range(1, epochs)]
summary = json.load(open(f"{work}/campaign/summary.json"))
labels = [e["label"] for e in summary["epochs"]]
rows = [("campaign, %d surveys, %d pairs" % (epochs, epochs - 1),) + camp]
for k, c in enumerate(comps):
    rows.append((f"compare {labels[k]} {labels[k + 1]}",) + c)
total = (sum(c[0] for c in comps), sum(c[1] for c in comps), max(c[2] for c in comps))
print(f"\n{epochs} surveys of {points:,} points (talus synth campaign), {os.cpu_count()} cores\n")
print("| run | wall (s) | CPU (s) | peak RSS (MiB) | load before |")
print("|---|---:|---:|---:|---:|")
for name, w, c, r, l in rows:
    print(f"| {name} | {w:.1f} | {c:.1f} | {r:.0f} | {l} |")
print(f"| {epochs - 1} compares, total (RSS: the largest) | {total[0]:.1f} | {total[1]:.1f} | {total[2]:.0f} | |")
print(f"| ratio campaign / compares | {camp[0] / total[0]:.2f} | {camp[1] / total[1]:.2f} | {camp[2] / total[2]:.2f} | |")
busy = [r for r in rows if float(r[4]) > (os.cpu_count() or 1) / 2]
if busy:
    print(f"\nwarning: the machine was busy (1-min load above half the cores) before {len(busy)} of "
          f"the {len(rows)} runs: wall times then include other processes' work; CPU seconds are "
          "the steadier figure.")
# The campaign's pairs against the compares' events (the campaign derives one parameter set from
# the first survey, each compare from its own before survey: close, not identical).
camp_csv = open(f"{work}/campaign/campaign.csv").read().splitlines()
head = camp_csv[0].split(",")
print("\n| pair | campaign events | compare events | campaign net m³ | compare net m³ |")
print("|---|---:|---:|---:|---:|")
for k, line in enumerate(camp_csv[1:]):
    c = dict(zip(head, line.split(",")))
    s = json.load(open(f"{work}/compare-{k + 1}/summary.json"))
    print(f"| {c['before']}_{c['after']} | {c['events']} | {s['events']} | {float(c['net_m3']):+.3f} | "
          f"{s['total_gain_m3'] + s['total_loss_m3']:+.3f} |")
PY
