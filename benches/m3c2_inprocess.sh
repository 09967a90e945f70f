#!/usr/bin/env bash
# talus.m3c2 against py4dgeo inside one Python process, on the same numpy arrays (see
# benches/README.md "Inside Python"): builds the wheel (release), installs it into the bench's
# venv beside py4dgeo, makes the data of m3c2_vs_py4dgeo.sh and runs py/inprocess.py.
# A benchmark, not a test: it exits non-zero only when it cannot run.
#
# Environment: ROUNDS (3), BENCH_WORK (bench-work/), THREADS (nproc), PY4DGEO_SPEC (py4dgeo==1.2.0).
set -euo pipefail

ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
WORK=${BENCH_WORK:-$ROOT/bench-work}
VENV=$ROOT/benches/.venv
PY=$VENV/bin/python
PY4DGEO_SPEC=${PY4DGEO_SPEC:-py4dgeo==1.2.0}

if [[ ! -x $PY ]]; then
    python3 -m venv "$VENV"
fi
if ! "$PY" -c "import py4dgeo, laspy, lazrs, numpy, pandas, maturin" 2>/dev/null; then
    "$PY" -m pip install --quiet "$PY4DGEO_SPEC" "laspy[lazrs]" numpy pandas "maturin>=1.5,<2"
fi
echo "### building the wheel (release)"
rm -rf "$WORK/wheel"
start=$(date +%s)
(cd "$ROOT/python" && "$VENV/bin/maturin" build --release --quiet -o "$WORK/wheel" -i "$PY")
wheel=$(ls "$WORK"/wheel/talus-*.whl)
echo "wheel: $(basename "$wheel"), $(du -k "$wheel" | cut -f1) KiB, built in $(($(date +%s) - start)) s"
"$PY" -m pip install --quiet --force-reinstall --no-deps "$wheel"
"$PY" "$ROOT/benches/py/make_data.py" "$WORK" --core-layout grid
"$PY" "$ROOT/benches/py/inprocess.py" "$WORK" --rounds "${ROUNDS:-3}" --threads "${THREADS:-$(nproc)}"
