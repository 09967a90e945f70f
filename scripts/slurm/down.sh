#!/usr/bin/env bash
# Stops the one-node cluster that up.sh started for $SLURM_STATE_DIR (default /tmp/talus-slurm):
#   1. cancels the jobs still queued or running, while slurmctld and slurmd are there to do it
#      (slurmd does not kill running jobs when it stops: their slurmstepd would live on);
#   2. stops slurmd, then slurmctld, by their pid files in the state dir;
#   3. kills any slurmstepd of this state dir that outlived slurmd, with its job's processes;
#   4. stops the private munged that up.sh started (same state dir).
# Only processes named by this state dir's pid files (or stepds writing to its slurmd.log) are
# touched; a system munged or another state dir's cluster is left alone. Idempotent: with nothing
# running it does nothing and exits 0. The state dir (logs, job-completion log) is kept.
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
# shellcheck source=common.sh
source "$here/common.sh"

[[ "$(id -u)" == 0 ]] || die "down.sh must run as root (the daemons run as root)"
export SLURM_CONF="$conf"

# ---------------------------------------------------------------- 1. cancel jobs
if pid_alive slurmctld "$ctld_pid" && pid_alive slurmd "$slurmd_pid" && [[ -f "$conf" ]]; then
  # Without -t, squeue lists the unfinished jobs (pending, running, suspended, completing).
  # %A is each array task's own job id, so every task is named.
  ids="$(squeue -h -o '%A' 2>/dev/null | sort -u | tr '\n' ' ' || true)"
  if [[ -n "${ids// /}" ]]; then
    note "cancelling jobs: $ids"
    # shellcheck disable=SC2086
    scancel $ids 2>/dev/null || true
    # KillWait=5 in slurm.conf: SIGTERM, then SIGKILL 5 s later; allow for the epilog too.
    for ((i = 0; i < 100; i++)); do
      [[ -z "$(squeue -h -o '%A' 2>/dev/null || true)" ]] && break
      sleep 0.3
    done
    left="$(squeue -h -o '%A %T' 2>/dev/null | tr '\n' ';' || true)"
    [[ -z "$left" ]] || note "jobs still not gone after 30 s ($left); stopping anyway"
  fi
fi

# ---------------------------------------------------------------- 2. slurm daemons
stop_daemon slurmd "$slurmd_pid"
stop_daemon slurmctld "$ctld_pid"

# ---------------------------------------------------------------- 3. orphaned step daemons
# A slurmstepd of this cluster keeps slurmd's log open (fd to $logdir/slurmd.log); that is how we
# tell it from another cluster's. Its job's processes are its descendants: kill those first.
our_stepds() {
  local p fd
  for p in /proc/[0-9]*; do
    [[ "$(cat "$p/comm" 2>/dev/null)" == slurmstepd ]] || continue
    for fd in "$p"/fd/*; do
      if [[ "$(readlink "$fd" 2>/dev/null)" == "$logdir/slurmd.log" ]]; then
        echo "${p#/proc/}"
        break
      fi
    done
  done
}
descendants() {
  # All descendants of $1, deepest last, from one ps snapshot.
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
stepds="$(our_stepds | tr '\n' ' ')"
if [[ -n "${stepds// /}" ]]; then
  note "killing leftover slurmstepd processes and their jobs: $stepds"
  for s in $stepds; do
    # shellcheck disable=SC2046
    kill -KILL $(descendants "$s") 2>/dev/null || true
    kill -KILL "$s" 2>/dev/null || true
  done
  sleep 0.5
  left="$(our_stepds | tr '\n' ' ')"
  [[ -z "${left// /}" ]] || die "slurmstepd processes survived SIGKILL: $left"
fi

# ---------------------------------------------------------------- 4. munged
stop_daemon munged "$munged_pid"

note "cluster down (state dir $state kept: logs in $logdir)"
