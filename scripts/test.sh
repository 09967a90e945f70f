#!/usr/bin/env bash
# Every test of talus, on a fresh machine: installs what the tests need (a Python venv with laspy
# and pyarrow for the independent-reader checks, the Python package's wheel in a fresh venv with
# py4dgeo, Debian chromium and the viewer's npm packages for the browser tests, Debian's Slurm and
# munge for the cluster test), then runs the Rust tests of the workspace, the Python package's tests,
# the viewer's browser tests and the Slurm executor against a real Slurm of one node, then two.
# This is the test command README.md gives; .ci/run calls it.
set -euo pipefail
repo="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$repo"

# Independent LAS and Parquet readers for the format tests (tests/py/.venv, gitignored): laspy,
# and pyarrow for a campaign's timeseries.parquet.
if ! tests/py/.venv/bin/python -c "import laspy, lazrs, pyarrow" 2>/dev/null; then
  echo "test.sh: creating tests/py/.venv with laspy and pyarrow" >&2
  python3 -m venv tests/py/.venv
  tests/py/.venv/bin/pip install --quiet --disable-pip-version-check 'laspy[lazrs]' pyarrow
fi
export TALUS_PYTHON="$repo/tests/py/.venv/bin/python"

cargo test --workspace --no-fail-fast

# No warning anywhere (the crates' `pub(crate)` items make dead code a warning: ARCHITECTURE.md
# "The crates"), in the Python crate either (its own workspace).
cargo clippy --workspace --all-targets -- -D warnings
(cd python && cargo clippy -- -D warnings)

# The documentation builds without a warning (broken or private intra-doc links, bad HTML).
RUSTDOCFLAGS="-D warnings" cargo doc --workspace --no-deps

# The Python package (python/, README.md "Python"): its wheel built and installed into a fresh
# venv with numpy, pandas, laspy and py4dgeo from PyPI; its numbers checked against the talus
# binary `cargo test` built and against py4dgeo. About 6 min on a fresh machine: the wheel's cold
# release build 3.5, the venv 1.5 (downloads), the tests 0.5.
bash python/tests/run.sh

# Browser tests of the web viewer (installs chromium and npm packages when missing).
bash viewer/tests/run.sh

# The Slurm executor against a real Slurm (installs and starts a one-node cluster, stops it
# again; fails, never skips, when Slurm cannot be installed or started). About 1.5 min, with the
# talus binary `cargo test` built (campaign.sh builds a release one when there is none).
# Cargo's target directory, wherever CARGO_TARGET_DIR or a config puts it.
target="$(cargo metadata --format-version 1 --no-deps \
  | python3 -c 'import json, sys; print(json.load(sys.stdin)["target_directory"])')"
if [[ -x "$target/debug/talus" ]]; then
  TALUS_BIN="$target/debug/talus" bash scripts/slurm/campaign.sh
else
  bash scripts/slurm/campaign.sh
fi

# The Slurm executor on two slurmd nodes (multiple-slurmd mode, its own state dir): a run across
# both, a node killed mid-task and the run finished by Slurm's requeue, and by --resume
# (scripts/slurm/README.md, "Two nodes"). About 3 min; the release binary campaign.sh built, or
# the debug one.
if [[ -x "$target/debug/talus" ]]; then
  TALUS_BIN="$target/debug/talus" bash scripts/slurm/nodes.sh
else
  TALUS_BIN="$target/release/talus" bash scripts/slurm/nodes.sh
fi
