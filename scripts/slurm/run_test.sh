# Shared by campaign.sh and nodes.sh (sourced after common.sh, with `test_name` set): how a test
# fails and prints, its inputs (the St Leonards surveys and the talus binary), its work folder and
# the comparison of a run's outputs with the local run's.
# shellcheck shell=bash
# shellcheck disable=SC2034 # surveys, talus and work are used by the scripts that source this file
# shellcheck disable=SC2154 # test_name, repo, here (the caller's) and state (common.sh's) are set before

fail() {
  echo "" >&2
  echo "******** $test_name FAILED: $* ********" >&2
  exit 1
}
section() { echo; echo "== $*"; }

# test_inputs: the six St Leonards surveys (`surveys`) and the binary (`talus`: TALUS_BIN, or a
# release build in cargo's target directory, wherever CARGO_TARGET_DIR or a config puts it).
test_inputs() {
  local data="$repo/tests/data/st-leonards" target
  [[ -d "$data" ]] || fail "no St Leonards data at $data (see tests/data/README.md)"
  mapfile -t surveys < <(ls "$data"/*.laz)
  [[ ${#surveys[@]} == 6 ]] || fail "expected 6 surveys in $data, found ${#surveys[@]}"
  if [[ -z "${TALUS_BIN:-}" ]]; then
    (cd "$repo" && cargo build --release --quiet --bin talus)
    target="$(cd "$repo" && cargo metadata --format-version 1 --no-deps \
      | python3 -c 'import json, sys; print(json.load(sys.stdin)["target_directory"])')"
    TALUS_BIN="$target/release/talus"
  fi
  talus="$(cd "$(dirname "$TALUS_BIN")" && pwd)/$(basename "$TALUS_BIN")"
  [[ -x "$talus" ]] || fail "no talus binary at $talus"
}

# work_in NAME: a fresh work folder $state/NAME (`work`), the current directory from then on.
work_in() {
  work="$state/$1"
  rm -rf "$work"
  mkdir -p "$work"
  cd "$work" || fail "cannot enter $work"
}

campaign() { "$talus" campaign "${surveys[@]}" "$@"; }

# local_reference: the campaign run locally into $work/local, what the Slurm runs must equal.
local_reference() {
  local t0=$SECONDS
  section "1. local run"
  campaign --out "$work/local" 2>"$work/local.err" || { cat "$work/local.err" >&2; fail "local run failed"; }
  tail -n 1 "$work/local.err"
  echo "local run: $((SECONDS - t0)) s"
}

# same_as_local NAME: $work/NAME holds the local run's outputs, byte for byte; its status.
same_as_local() {
  python3 "$here/same_outputs.py" "$work/local" "$work/$1" >"$work/same-$1.txt" \
    || { cat "$work/same-$1.txt"; fail "the outputs of run '$1' differ from the local run's"; }
  tail -n 1 "$work/same-$1.txt"
  "$talus" status "$work/$1"
}
