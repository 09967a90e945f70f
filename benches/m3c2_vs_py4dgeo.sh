#!/usr/bin/env bash
# Side-by-side speed benchmark of talus M3C2 against py4dgeo (see benches/README.md).
#
# Times whole processes of `talus compare` and of a py4dgeo script, alternating, on the same
# LAS files (2 x 1M points of a rough surface, 100k core points from a file, normal radius 1.0,
# cylinder radius 0.5, half-length 3.0), then prints wall times, CPU times, peak RSS, their
# ratios and the agreement of the distances. A benchmark, not a test: it exits 0 whether or not
# the goals are met; it exits non-zero only when it cannot run (build, pip, a tool failing).
#
# Environment: ROUNDS (3), BENCH_WORK (bench-work/), THREADS (nproc), WARMUP (1 = one untimed
# run of each tool first), QUIET_LOAD (unset; if set, wait before each timed run until the
# 1-min load average is below it, at most 10 min), PY4DGEO_SPEC (py4dgeo==1.2.0),
# REFERENCE_SAMPLE (2000 core points for the brute-force check; 0 = skip), ALIGN (off: talus's
# --align, auto to time its alignment too).
set -euo pipefail

ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
WORK=${BENCH_WORK:-$ROOT/bench-work}
ROUNDS=${ROUNDS:-3}
THREADS=${THREADS:-$(nproc)}
WARMUP=${WARMUP:-1}
QUIET_LOAD=${QUIET_LOAD:-}
# The version whose sources run_py4dgeo.py's settings were checked against.
PY4DGEO_SPEC=${PY4DGEO_SPEC:-py4dgeo==1.2.0}
REFERENCE_SAMPLE=${REFERENCE_SAMPLE:-2000}
VENV=$ROOT/benches/.venv
PY=$VENV/bin/python
HELPERS=$ROOT/benches/py
TIME=/usr/bin/time

# The benchmark's parameters (the issue's): both tools get exactly these.
NORMAL_RADIUS=1.0
CYL_RADIUS=0.5
CYL_HALFLEN=3.0

say() { printf '\n### %s\n' "$*"; }
die() {
    printf 'error: %s\n' "$*" >&2
    exit 1
}

# ---- 1. talus, release build
say "building talus (release)"
(cd "$ROOT" && cargo build --release --bin talus) || die "cargo build --release failed"
TALUS=${CARGO_TARGET_DIR:-$ROOT/target}/release/talus
[[ -x $TALUS ]] || die "no talus binary at $TALUS"

# ---- GNU time (for wall time and peak RSS of whole processes)
if [[ ! -x $TIME ]]; then
    say "installing GNU time"
    if [[ $(id -u) -eq 0 ]]; then
        (apt-get update -qq && apt-get install -y -qq time) || die "apt-get install time failed"
    elif command -v sudo >/dev/null; then
        (sudo apt-get update -qq && sudo apt-get install -y -qq time) || die "apt-get install time failed"
    else
        die "/usr/bin/time is missing: install the 'time' package"
    fi
fi

# ---- 2. the py4dgeo venv
say "python venv $VENV"
if [[ ! -x $PY ]]; then
    python3 -m venv "$VENV" || die "python3 -m venv failed (is python3-venv installed?)"
fi
if ! "$PY" -c "import py4dgeo, laspy, lazrs, numpy, scipy" 2>/dev/null; then
    "$PY" -m pip install --quiet --upgrade pip >/dev/null 2>&1 || true
    if ! "$PY" -m pip install --quiet "$PY4DGEO_SPEC" "laspy[lazrs]" numpy scipy; then
        die "pip install of $PY4DGEO_SPEC, laspy[lazrs], numpy, scipy failed: is PyPI reachable from here? (a mirror can be set with PIP_INDEX_URL)"
    fi
fi
"$PY" -c "import py4dgeo, laspy, numpy; print('py4dgeo', py4dgeo.__version__, '| laspy', laspy.__version__, '| numpy', numpy.__version__)"

# ---- 3. data
say "data in $WORK"
"$PY" "$HELPERS/make_data.py" "$WORK" --core-layout "${CORE_LAYOUT:-grid}"
BEFORE=$WORK/before.las
AFTER=$WORK/after.las
CORES=$WORK/cores.las
TALUS_OUT=$WORK/talus-out
PY_OUT=$WORK/py4dgeo-out
TIMES=$WORK/times
LOGS=$WORK/logs
rm -rf "$TIMES" "$LOGS"
mkdir -p "$TIMES" "$LOGS"

# --align off: py4dgeo's M3C2 takes the epochs as given, so talus does too here (its alignment on
# the stable ground, a sample's M3C2 and a rigid fit, is measured apart: ALIGN=auto).
talus_cmd=("$TALUS" compare "$BEFORE" "$AFTER" --out "$TALUS_OUT" --force
    --core-points "$CORES" --normal-radius "$NORMAL_RADIUS" --cyl-radius "$CYL_RADIUS"
    --cyl-halflen "$CYL_HALFLEN" --orientation up --threads "$THREADS" --m3c2-only
    --align "${ALIGN:-off}")
py_cmd=(env OMP_NUM_THREADS="$THREADS" OMP_PROC_BIND=false "$PY" "$HELPERS/run_py4dgeo.py"
    "$BEFORE" "$AFTER" "$CORES" "$PY_OUT" --normal-radius "$NORMAL_RADIUS"
    --cyl-radius "$CYL_RADIUS" --cyl-halflen "$CYL_HALFLEN")

wait_quiet() {
    [[ -n $QUIET_LOAD ]] || return 0
    local waited=0
    while awk -v q="$QUIET_LOAD" '{ exit !($1 >= q) }' /proc/loadavg && ((waited < 600)); do
        sleep 10
        waited=$((waited + 10))
    done
}

# run TOOL TAG: one whole process of TOOL under /usr/bin/time -v; TAG names its files.
run() {
    local tool=$1 tag=$2
    local -a cmd
    if [[ $tool == talus ]]; then cmd=("${talus_cmd[@]}"); else cmd=("${py_cmd[@]}"); fi
    wait_quiet
    cat /proc/loadavg >"$TIMES/$tag.load"
    if ! "$TIME" -v -o "$TIMES/$tag.time" "${cmd[@]}" >"$LOGS/$tag.log" 2>&1; then
        tail -n 20 "$LOGS/$tag.log" >&2
        die "$tool failed (log: $LOGS/$tag.log, time: $TIMES/$tag.time)"
    fi
    awk -F': ' '/Elapsed \(wall clock\)/ { w = $2 } /Maximum resident/ { m = $2 }
        END { printf "  %-16s wall %s  peak RSS %.1f MiB\n", tag, w, m / 1024 }' tag="$tag" \
        "$TIMES/$tag.time"
}

# ---- 4. timed runs, alternating (ABBA order so neither tool always runs first)
say "machine: $(nproc) cores, $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | sed 's/^ *//'); threads per tool: $THREADS; rounds: $ROUNDS"
echo "talus commit: $(git -C "$ROOT" rev-parse --short HEAD 2>/dev/null || echo unknown)"
if [[ $WARMUP == 1 ]]; then
    say "warm-up (untimed: page cache, python bytecode)"
    run talus warmup_talus
    run py4dgeo warmup_py4dgeo
    rm -f "$TIMES"/warmup_*
fi
say "timed runs"
for ((r = 1; r <= ROUNDS; r++)); do
    if ((r % 2 == 1)); then order=(talus py4dgeo); else order=(py4dgeo talus); fi
    for tool in "${order[@]}"; do run "$tool" "${tool}_$r"; done
done

# ---- 5./6. report
say "report"
"$PY" "$HELPERS/compare.py" --times "$TIMES" --talus-out "$TALUS_OUT" --py-out "$PY_OUT" \
    --cores "$CORES" --before "$BEFORE" --after "$AFTER" \
    --cyl-radius "$CYL_RADIUS" --cyl-halflen "$CYL_HALFLEN" \
    --reference-sample "$REFERENCE_SAMPLE" || die "compare.py failed"
exit 0
