#!/usr/bin/env bash
# Browser tests of the web viewer: installs what they need (Debian chromium, the npm packages),
# builds the server example and runs `node --test viewer/tests/`. Called by the project's test
# command; safe to re-run (every step is skipped when already done).
set -euo pipefail

here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
viewer="$(dirname "$here")"
repo="$(dirname "$viewer")"

if [ ! -x /usr/bin/chromium ]; then
  echo "run.sh: installing chromium" >&2
  sudo_cmd=""
  if [ "$(id -u)" -ne 0 ]; then sudo_cmd="sudo"; fi
  $sudo_cmd env DEBIAN_FRONTEND=noninteractive apt-get update -q
  $sudo_cmd env DEBIAN_FRONTEND=noninteractive apt-get install -y -q chromium
fi

if [ ! -d "$viewer/node_modules/three" ] || [ ! -d "$viewer/node_modules/playwright-core" ]; then
  (cd "$viewer" && npm ci --no-audit --no-fund)
fi

if [ -z "${TALUS_VIEW_CMD:-}" ]; then
  (cd "$repo" && cargo build --quiet --example view_server)
fi
# The real-result test runs the talus binary (synth, compare, view).
(cd "$repo" && cargo build --quiet --bin talus)

cd "$repo"
exec node --test viewer/tests/
