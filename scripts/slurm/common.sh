# Shared by up.sh, down.sh and selftest.sh (sourced, not run). Defines the state-dir layout and the
# pid-file helpers, so that the three scripts agree on where everything lives.
# shellcheck disable=SC2034 # the paths are used by the scripts that source this file

# Everything the cluster writes lives under one directory, so that a run never touches
# /etc/slurm, /var/spool or /run and two state dirs never share a file.
SLURM_STATE_DIR="${SLURM_STATE_DIR:-/tmp/talus-slurm}"
# Absolute, because the daemons chdir and the path ends up in slurm.conf.
case "$SLURM_STATE_DIR" in
  /*) ;;
  *) SLURM_STATE_DIR="$(pwd)/$SLURM_STATE_DIR" ;;
esac
# slurm.conf has no quoting: a path with blanks would be cut at the first one.
[[ "$SLURM_STATE_DIR" != *[[:space:]]* ]] || { echo "talus slurm: ERROR: SLURM_STATE_DIR has blanks: '$SLURM_STATE_DIR'" >&2; exit 1; }
state="$SLURM_STATE_DIR"
conf="$state/slurm.conf"
rundir="$state/run"          # pid files
logdir="$state/log"          # daemon logs and the job-completion log
mungedir="$state/munge"      # munged's socket (must be 0755: munged checks it)
keydir="$state/munge-key"    # munge key (0700, key 0400)
munge_socket="$mungedir/munge.socket"
munge_key="$keydir/munge.key"
jobcomp_log="$logdir/jobcomp.txt"

die() {
  # Loud on purpose: a caller (a test) must fail, never pass quietly, when the cluster is not there.
  echo "" >&2
  echo "******** talus slurm: ERROR: $* ********" >&2
  exit 1
}
note() { echo "talus slurm: $*" >&2; }

# proc_is NAME PID: true when PID is a live (not zombie) process whose command is NAME. Checking
# the command, not just `kill -0`, is what keeps a stale pid file from a previous boot or a killed
# run from blocking a start or killing an unrelated process that got the same pid.
proc_is() {
  local name="$1" pid="$2" stat
  [[ -n "$pid" ]] || return 1
  [[ "$(cat "/proc/$pid/comm" 2>/dev/null)" == "$name" ]] || return 1
  # A zombie (exited, not yet reaped) is dead for our purposes. /proc/PID/stat is
  # "pid (comm) state ...": the state is the first field after the closing parenthesis.
  stat="$(cat "/proc/$pid/stat" 2>/dev/null)" || return 1
  stat="${stat##*) }"
  [[ "${stat%% *}" != Z ]]
}

# live_pid NAME PIDFILE: prints the pid PIDFILE names if that process is alive and is NAME;
# fails (prints nothing) for a missing, empty or stale pid file.
live_pid() {
  local name="$1" file="$2" pid
  [[ -r "$file" ]] || return 1
  pid="$(tr -dc "0-9" <"$file")"
  proc_is "$name" "$pid" || return 1
  echo "$pid"
}
pid_alive() { live_pid "$1" "$2" >/dev/null; }
pid_of() { [[ -r "$1" ]] && tr -dc "0-9" <"$1"; }

# stop_daemon NAME PIDFILE: SIGTERM the process the pid file names (only if it is really NAME),
# wait for it to go, SIGKILL after 30 s, then remove the pid file. A missing or stale pid file is
# not an error: stopping is idempotent. The pid is read once: daemons delete their own pid file
# as they exit.
stop_daemon() {
  local name="$1" file="$2" pid i
  if pid="$(live_pid "$name" "$file")"; then
    note "stopping $name (pid $pid)"
    kill -TERM "$pid" 2>/dev/null || true
    for ((i = 0; i < 150; i++)); do
      proc_is "$name" "$pid" || break
      sleep 0.2
    done
    if proc_is "$name" "$pid"; then
      note "$name (pid $pid) ignored SIGTERM for 30 s; sending SIGKILL"
      kill -KILL "$pid" 2>/dev/null || true
      for ((i = 0; i < 50; i++)); do
        proc_is "$name" "$pid" || break
        sleep 0.2
      done
      proc_is "$name" "$pid" && die "$name (pid $pid) survived SIGKILL"
    fi
    # Give init a moment to reap it, so that `ps` right after shows no <defunct> entry.
    for ((i = 0; i < 25; i++)); do
      [[ -e "/proc/$pid" ]] || break
      sleep 0.2
    done
  fi
  rm -f "$file"
}

# The daemons' pid files (paths also written into slurm.conf / munged's command line).
ctld_pid="$rundir/slurmctld.pid"
slurmd_pid="$rundir/slurmd.pid"
munged_pid="$rundir/munged.pid"

# teardown_on_exit LABEL STOP: the EXIT trap of a test script (trap 'teardown_on_exit ... ' EXIT).
# With STOP non-empty, stops the cluster (down.sh; a failure there fails the test); on a non-zero
# exit, says loudly that LABEL failed and where the daemon logs are. Exits with the test's status.
teardown_on_exit() {
  local rc=$? label="$1" stop="$2"
  if [[ -n "$stop" ]]; then
    echo
    echo "== teardown (down.sh)"
    bash "$(dirname "${BASH_SOURCE[0]}")/down.sh" || rc=1
  fi
  if [[ $rc != 0 ]]; then
    echo "******** $label FAILED (exit $rc); daemon logs: $logdir ********" >&2
  fi
  exit $rc
}
