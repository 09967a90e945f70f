#!/usr/bin/env bash
# The Python package's tests (scripts/test.sh runs this after `cargo test`): builds the wheel
# with maturin, installs it into a fresh venv with numpy, pandas, geopandas, laspy and py4dgeo
# from PyPI, and runs python/tests with pytest against the talus binary `cargo test` built
# (TALUS_BIN; the newest under the target directory otherwise).
#
# The wheel is the release build users get (PROFILE overrides the profile). Python venvs and the
# wheel live in python/.venv-*/ and python/dist/ (gitignored).
set -euo pipefail
repo="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
cd "$repo"
py=python/.venv-test/bin/python
profile=${PROFILE:-release}
start=$SECONDS

# maturin in a venv of its own (kept between runs).
if ! python/.venv-build/bin/maturin --version >/dev/null 2>&1; then
  echo "python tests: creating python/.venv-build with maturin" >&2
  python3 -m venv python/.venv-build
  python/.venv-build/bin/pip install --quiet --disable-pip-version-check 'maturin>=1.5,<2'
fi
target="$(cargo metadata --format-version 1 --no-deps \
  | python3 -c 'import json, sys; print(json.load(sys.stdin)["target_directory"])')"
rm -rf python/dist
t=$SECONDS
(cd python && CARGO_TARGET_DIR="$target" .venv-build/bin/maturin build --quiet \
  --profile "$profile" -o dist -i .venv-build/bin/python)
wheel=$(ls python/dist/talus-*.whl)
echo "python tests: built $(basename "$wheel") ($(du -k "$wheel" | cut -f1) KiB, profile $profile) in $((SECONDS - t)) s" >&2

# A fresh venv: the wheel installs with its own dependencies, and the tests' beside it.
t=$SECONDS
rm -rf python/.venv-test
python3 -m venv python/.venv-test
$py -m pip install --quiet --disable-pip-version-check "$wheel" 'laspy[lazrs]' py4dgeo geopandas pytest
echo "python tests: venv in $((SECONDS - t)) s ($($py -c 'import numpy, pandas, py4dgeo; print("numpy", numpy.__version__, "pandas", pandas.__version__, "py4dgeo", py4dgeo.__version__)'))" >&2

if [[ -z ${TALUS_BIN:-} && -x "$target/debug/talus" ]]; then
  export TALUS_BIN="$target/debug/talus"
fi
# From the repository's root, so that `import talus` is the installed wheel, not python/talus.
python/.venv-test/bin/pytest -p no:cacheprovider -q python/tests
echo "python tests: $((SECONDS - start)) s in all" >&2
