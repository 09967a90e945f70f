# shellcheck shell=bash
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

# TALUS_SLURM_NODES=N (default 1): with N >= 2, up.sh starts N slurmd daemons on this machine in
# Slurm's multiple-slurmd mode (Debian's slurmd is built with it: `scontrol show config` says
# MULTIPLE_SLURMD = Yes), as nodes node1..nodeN, each with its own port, spool dir, pid file
# (slurmd_pid_of) and log (slurmd_log_of), and this machine's CPUs and memory split between
# them. With 1, the cluster is the one node named after this host, exactly as before.
slurm_nodes="${TALUS_SLURM_NODES:-1}"
[[ "$slurm_nodes" =~ ^[1-9][0-9]?$ ]] || { echo "talus slurm: ERROR: TALUS_SLURM_NODES must be 1..99, not '$slurm_nodes'" >&2; exit 1; }
# node_names: the Slurm names of the nodes of a multi-node cluster (node1 .. nodeN).
node_names() { local i; for ((i = 1; i <= slurm_nodes; i++)); do echo "node$i"; done; }
# slurmd_pid_of NODE / slurmd_log_of NODE: a multi-node cluster's slurmd NODE's pid file and log
# (slurm.conf's SlurmdPidFile and SlurmdLogFile with %n, which slurmd replaces by its node name).
slurmd_pid_of() { echo "$rundir/slurmd-$1.pid"; }
slurmd_log_of() { echo "$logdir/slurmd-$1.log"; }
# all_slurmd_pids: the pid files of every slurmd this state dir may have (one node or several).
all_slurmd_pids() { compgen -G "$rundir/slurmd*.pid" || true; }

# stepds_of LOG...: the slurmstepd processes of this machine that keep one of the slurmd logs LOG
# open. slurmd's log is how a step daemon is told apart from another cluster's (or another
# node's): it inherits slurmd's open log file and outlives slurmd when slurmd is killed.
stepds_of() {
  local p fd target log
  for p in /proc/[0-9]*; do
    [[ "$(cat "$p/comm" 2>/dev/null)" == slurmstepd ]] || continue
    for fd in "$p"/fd/*; do
      target="$(readlink "$fd" 2>/dev/null)" || continue
      for log in "$@"; do
        if [[ "$target" == "$log" ]]; then
          echo "${p#/proc/}"
          continue 3
        fi
      done
    done
  done
}
# descendants PID: all descendants of PID, deepest last, from one ps snapshot.
descendants() {
  local -A kids=()
  local pid ppid queue=("$1") cur
  while read -r pid ppid; do kids[$ppid]+="$pid "; done < <(ps -e -o pid=,ppid=)
  while ((${#queue[@]})); do
    cur="${queue[0]}"
    queue=("${queue[@]:1}")
    for pid in ${kids[$cur]:-}; do
      echo "$pid"
      queue+=("$pid")
    done
  done
}

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
