#!/usr/bin/env bash
# The smallest --memory that works for a pair (issue 24): start at the smallest budget talus
# accepts, follow each refusal's "the smallest budget that works is --memory N" until a run
# completes, then check that one MiB less is refused. Prints each run and the result.
#
#   bash benches/smallest_budget.sh BEFORE AFTER [TALUS]    # TALUS: the binary (default: release)
set -euo pipefail
repo="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
before="$1"; after="$2"; talus="${3:-$repo/target/release/talus}"
work="$(mktemp -d "${TMPDIR:-/tmp}/smallest.XXXXXX")"
trap 'rm -rf "$work"' EXIT
run() { # run BUDGET_MIB -> prints "ok", or the suggested budget
  local b="$1" err
  if err=$("$talus" compare "$before" "$after" --out "$work/res-$b" --force --memory "${b}MiB" 2>&1 >/dev/null); then
    echo ok
  else
    local s
    s=$(printf '%s\n' "$err" | grep -o 'the smallest budget that works is --memory [0-9]*MiB' | grep -o '[0-9]*' | tail -1 || true)
    [ -n "$s" ] || { printf '%s\n' "$err" >&2; exit 1; }
    echo "$s"
  fi
  rm -rf "$work/res-$b"
}
b=160
while :; do
  r=$(run "$b")
  echo "--memory ${b}MiB: ${r/ok/completes}" >&2
  [ "$r" = ok ] && break
  [ "$r" -gt "$b" ] || { echo "refused at $b MiB naming $r MiB" >&2; exit 1; }
  b="$r"
done
r=$(run $((b - 1)))
echo "--memory $((b - 1))MiB: ${r/ok/completes}" >&2
[ "$r" = ok ] && { echo "one MiB less also works: not the smallest" >&2; exit 1; }
echo "smallest budget: ${b} MiB"
