#!/usr/bin/env bash
# Disk benchmark (issue 46, "disk bounded by the inputs"): what DIR holds after a run and at its
# peak, against the inputs' size, with the intermediate units released (the default) and kept
# (`--keep-units`). The peak is `du -sb DIR` sampled every 0.3 s while the run goes (a sample can
# miss a short-lived high; the figure is a lower bound of the true peak).
#
#   bash benches/disk.sh                      # the pair of `talus synth large --points 10000000`
#   POINTS=120000000 bash benches/disk.sh     # the 120M-point pair (benches/scale.sh's size)
#   DISK_WORK=/path bash benches/disk.sh      # where the data goes (default bench-work/disk)
set -euo pipefail
repo="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$repo"
source benches/common.sh disk.sh
POINTS="${POINTS:-10000000}"
WORK="${DISK_WORK:-$repo/bench-work/disk}"
mkdir -p "$WORK"
scene="$WORK/large-$POINTS"
if [ ! -f "$scene/truth.json" ]; then
  echo "disk.sh: synth large --points $POINTS" >&2
  "$talus" synth large --points "$POINTS" --out "$scene" >/dev/null
fi
inputs=$(($(stat -c %s "$scene/before.laz") + $(stat -c %s "$scene/after.laz")))

# Run `talus compare` into $1 with the extra arguments after it; print "after peak" in bytes.
measure() {
  local out="$1"
  shift
  rm -rf "$out"
  "$talus" compare "$scene/before.laz" "$scene/after.laz" --out "$out" "$@" 2>"$out.err" &
  local pid=$! peak=0 s
  while kill -0 "$pid" 2>/dev/null; do
    s=$(du -sb "$out" 2>/dev/null | cut -f1 || true)
    [ -n "$s" ] && [ "$s" -gt "$peak" ] && peak=$s
    sleep 0.3
  done
  wait "$pid" || { cat "$out.err" >&2; exit 1; }
  s=$(du -sb "$out" | cut -f1)
  [ "$s" -gt "$peak" ] && peak=$s
  echo "$s $peak"
}

ratio() { awk -v a="$1" -v b="$inputs" 'BEGIN { printf "%.2f", a / b }'; }
printf '%-28s %12s %7s %12s %7s\n' "run ($POINTS points/epoch)" "after (MB)" "×in" "peak (MB)" "×in"
for mode in released kept; do
  args=()
  [ "$mode" = kept ] && args=(--keep-units)
  read -r after peak < <(measure "$WORK/res-$mode" "${args[@]}")
  printf '%-28s %12.1f %7s %12.1f %7s\n' "compare, units $mode" "$(echo "$after / 1000000" | bc -l)" \
    "$(ratio "$after")" "$(echo "$peak / 1000000" | bc -l)" "$(ratio "$peak")"
done
echo "inputs: $(echo "$inputs / 1000000" | bc -l | xargs printf '%.1f') MB of LAZ; m3c2.laz: $(stat -c %s "$WORK/res-released/m3c2.laz") bytes"
