# Sourced by the whole-process benchmarks: GNU time (installed with apt-get when missing and
# running as root), the release build, and `talus` = its binary. The caller has cd'ed to the
# repository; $1 names the script in messages.
if [ ! -x /usr/bin/time ]; then
  echo "$1: installing GNU time" >&2
  DEBIAN_FRONTEND=noninteractive apt-get install -y -q time >/dev/null
fi
cargo build --release --quiet
talus="$PWD/target/release/talus"
