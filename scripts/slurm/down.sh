#!/usr/bin/env bash
# Stops the cluster (one node, or several: TALUS_SLURM_NODES) that up.sh started for $SLURM_STATE_DIR (default /tmp/talus-slurm):
#   1. cancels the jobs still queued or running, while slurmctld and slurmd are there to do it
#      (slurmd does not kill running jobs when it stops: their slurmstepd would live on);
#   2. stops every slurmd, then slurmctld, by their pid files in the state dir;
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
# A slurmd of any node (one, or several with TALUS_SLURM_NODES) alive: the jobs can be cancelled.
any_slurmd=""
for f in $(all_slurmd_pids); do pid_alive slurmd "$f" && any_slurmd=1; done
if pid_alive slurmctld "$ctld_pid" && [[ -n "$any_slurmd" ]] && [[ -f "$conf" ]]; then
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
# Every slurmd pid file of the state dir: slurmd.pid (one node), slurmd-nodeI.pid (several).
for f in $(all_slurmd_pids); do stop_daemon slurmd "$f"; done
stop_daemon slurmctld "$ctld_pid"

# ---------------------------------------------------------------- 3. orphaned step daemons
# A slurmstepd of this cluster keeps its slurmd's log open ($logdir/slurmd.log, or
# slurmd-nodeI.log of a multi-node cluster; common.sh stepds_of); that is how we tell it from
# another cluster's. Its job's processes are its descendants (descendants): kill those first.
our_stepds() {
  local logs
  mapfile -t logs < <(compgen -G "$logdir/slurmd*.log" || true)
  ((${#logs[@]})) || return 0
  stepds_of "${logs[@]}"
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
