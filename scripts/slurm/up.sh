#!/usr/bin/env bash
# Brings up a one-node Slurm cluster on this machine for talus's tests, idempotently:
#   - installs Debian's slurmctld, slurmd, slurm-client and munge when missing;
#   - starts a private munged (own key and socket in the state dir, so it never clashes with, or
#     depends on, a system munged);
#   - writes $SLURM_STATE_DIR/slurm.conf for this node (real hostname, CPUs, memory);
#   - starts slurmctld and slurmd by hand (no systemd here) and waits until the node is idle.
# Run again while it is up: checks it and changes nothing (restarts the Slurm daemons only if
# the generated slurm.conf changed). Stale pid files from a killed run are ignored.
#
# Prints on stdout the exports a caller needs (eval "$(scripts/slurm/up.sh)"); the same lines are
# written to $SLURM_STATE_DIR/env.sh. Everything else goes to stderr.
#
# Environment:
#   SLURM_STATE_DIR       state dir (default /tmp/talus-slurm)
#   TALUS_SLURMCTLD_PORT  slurmctld port (default 6817)
#   TALUS_SLURMD_PORT     slurmd port (default 6818)
#   TALUS_SLURM_TIMEOUT   seconds to wait for the node to be idle (default 60)
#   TALUS_SLURM_MIN_JOB_AGE  seconds a finished job stays queryable in squeue/scontrol (default 600)
#
# Exits non-zero with a loud message when Slurm cannot be installed or started.
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
# shellcheck source=common.sh
source "$here/common.sh"

ctld_port="${TALUS_SLURMCTLD_PORT:-6817}"
slurmd_port="${TALUS_SLURMD_PORT:-6818}"
timeout="${TALUS_SLURM_TIMEOUT:-60}"
min_job_age="${TALUS_SLURM_MIN_JOB_AGE:-600}"

# Installing packages and running slurmd (which starts jobs as any user) needs root.
[[ "$(id -u)" == 0 ]] || die "up.sh must run as root (apt-get, slurmd)"

# ---------------------------------------------------------------- install
have_all() {
  local c
  for c in slurmctld slurmd sbatch squeue scontrol sinfo munged munge mungekey; do
    command -v "$c" >/dev/null 2>&1 || return 1
  done
}
if ! have_all; then
  command -v apt-get >/dev/null 2>&1 || die "Slurm is not installed and there is no apt-get to install it"
  note "installing slurmctld slurmd slurm-client munge (Debian packages)"
  # Keep the packages' maintainer scripts from starting their own daemons (they would take the
  # default ports and /run/munge). Docker-style images already have a policy-rc.d that says 101
  # ("action forbidden"); add one only for the install if there is none, and remove it after.
  added_policy=""
  if [[ ! -e /usr/sbin/policy-rc.d ]]; then
    printf '#!/bin/sh\nexit 101\n' >/usr/sbin/policy-rc.d
    chmod 755 /usr/sbin/policy-rc.d
    added_policy=1
  fi
  apt_install() {
    DEBIAN_FRONTEND=noninteractive apt-get install -y -q slurmctld slurmd slurm-client munge \
      >"${TMPDIR:-/tmp}/talus-slurm-apt.log" 2>&1
  }
  # apt-get update only when the package lists are missing or the install fails with the ones
  # there (an old list names versions the mirror no longer has).
  apt_update() { apt-get update -q >"${TMPDIR:-/tmp}/talus-slurm-apt-update.log" 2>&1 || true; }
  if ! compgen -G '/var/lib/apt/lists/*Packages*' >/dev/null; then
    apt_update
  fi
  rc=0
  apt_install || { apt_update; apt_install; } || rc=$?
  [[ -n "$added_policy" ]] && rm -f /usr/sbin/policy-rc.d
  if [[ $rc != 0 ]] || ! have_all; then
    tail -n 20 "${TMPDIR:-/tmp}/talus-slurm-apt.log" >&2 || true
    die "could not install Slurm/munge with apt-get (log: ${TMPDIR:-/tmp}/talus-slurm-apt.log)"
  fi
fi

# ---------------------------------------------------------------- state dir
# From here on, a failure stops whatever daemons of this state dir are running (down.sh), so
# that a failed start leaves no half cluster behind; the logs stay in the state dir.
trap 'rc=$?; if ((rc != 0)); then note "start failed: stopping what was started"; bash "$here/down.sh" >&2 || true; fi; exit $rc' EXIT
mkdir -p "$state" "$rundir" "$logdir" "$mungedir" "$keydir" "$state/spool/slurmctld" "$state/spool/slurmd"
# munged refuses a socket dir that others cannot traverse, and a key dir/key others can read.
chmod 755 "$state" "$mungedir"
chmod 700 "$keydir"

# ---------------------------------------------------------------- munge
if [[ ! -s "$munge_key" ]]; then
  note "creating munge key $munge_key"
  rm -f "$munge_key"
  mungekey --create --keyfile="$munge_key" || die "mungekey could not create $munge_key"
fi
chmod 400 "$munge_key"

munge_works() { munge -n -S "$munge_socket" 2>/dev/null | unmunge -S "$munge_socket" >/dev/null 2>&1; }
if pid_alive munged "$munged_pid" && munge_works; then
  note "munged already running (pid $(pid_of "$munged_pid"))"
else
  # A munged of ours that is alive but not answering is stopped; a stale pid file or socket from
  # a killed run is removed, so that the new munged can take the socket.
  stop_daemon munged "$munged_pid"
  rm -f "$munge_socket" "$munge_socket.lock"
  note "starting munged (socket $munge_socket)"
  munged --socket="$munge_socket" --key-file="$munge_key" --pid-file="$munged_pid" \
    --log-file="$logdir/munged.log" --seed-file="$keydir/munged.seed" \
    || { tail -n 5 "$logdir/munged.log" >&2 || true; die "munged did not start (log: $logdir/munged.log)"; }
  for ((i = 0; i < 50; i++)); do munge_works && break; sleep 0.1; done
  munge_works || die "munged started but does not answer on $munge_socket (log: $logdir/munged.log)"
fi

# ---------------------------------------------------------------- slurm.conf
# `slurmd -C` prints this node as slurmd sees it (hostname, sockets/cores/threads, RealMemory);
# its NodeName line goes into slurm.conf unchanged, so the node never drains for "low memory" or a
# CPU count that differs from the configured one.
node_line="$(slurmd -C 2>/dev/null | grep '^NodeName=')" || die "slurmd -C printed no NodeName line"
node_name="$(sed -E 's/^NodeName=([^ ]+).*/\1/' <<<"$node_line")"
host_short="$(hostname -s)"
[[ "$node_name" == "$host_short" ]] || note "warning: slurmd -C names the node $node_name, hostname -s says $host_short"

# Ports: the defaults (or TALUS_SLURMCTLD_PORT / TALUS_SLURMD_PORT). When this script's own
# daemons are not running and a default port is taken (another Slurm on this machine listens on
# 6817/6818), a free port is picked instead and said; a port the caller set is used as given.
port_busy() {
  python3 - "$1" <<'PY'
import socket, sys
s = socket.socket()
s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
try:
    s.bind(("0.0.0.0", int(sys.argv[1])))
except OSError:
    sys.exit(0)
sys.exit(1)
PY
}
free_port() {
  python3 -c 'import socket; s = socket.socket(); s.bind(("", 0)); print(s.getsockname()[1])'
}
if ! pid_alive slurmctld "$ctld_pid" && ! pid_alive slurmd "$slurmd_pid"; then
  if [[ -z "${TALUS_SLURMCTLD_PORT:-}" ]] && port_busy "$ctld_port"; then
    old="$ctld_port"; ctld_port="$(free_port)"
    note "port $old is taken (another Slurm?): slurmctld listens on $ctld_port instead"
  fi
  if [[ -z "${TALUS_SLURMD_PORT:-}" ]] && port_busy "$slurmd_port"; then
    old="$slurmd_port"; slurmd_port="$(free_port)"
    while [[ "$slurmd_port" == "$ctld_port" ]]; do slurmd_port="$(free_port)"; done
    note "port $old is taken (another Slurm?): slurmd listens on $slurmd_port instead"
  fi
elif [[ -f "${conf:-}" ]]; then
  # Our daemons run: keep the ports they were started with.
  ctld_port="$(sed -n 's/^SlurmctldPort=//p' "$conf" | head -n 1)"
  slurmd_port="$(sed -n 's/^SlurmdPort=//p' "$conf" | head -n 1)"
fi

new_conf="$(cat <<EOF
# Written by talus scripts/slurm/up.sh; rewritten on every run (edit up.sh, not this file).
ClusterName=talus
SlurmctldHost=$node_name
SlurmctldPort=$ctld_port
SlurmdPort=$slurmd_port
# Daemons and jobs as root: this is a throw-away test cluster on a machine where we are root.
SlurmUser=root
SlurmdUser=root
# Private munged (see up.sh); clients read the socket from here too, so they need SLURM_CONF.
AuthType=auth/munge
CredType=cred/munge
AuthInfo=socket=$munge_socket
# No cgroups: linuxproc tracks a job's processes by parent pid, task/none binds nothing.
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
# No slurmdbd, so sacct has no accounting database. The job-completion log (one line per
# finished job, with its final state) is what sacct --completion (-c) reads instead.
AccountingStorageType=accounting_storage/none
JobCompType=jobcomp/filetxt
JobCompLoc=$jobcomp_log
MpiDefault=none
# No mail on this machine; the default /bin/mail is missing and slurmctld logs an error for it.
MailProg=/bin/true
# Cores and memory are consumable: two 1-CPU jobs run at once on 2 cores and --mem is checked
# against RealMemory. DefMemPerCPU: without it a job that gives no --mem is allocated the whole
# node's memory, and jobs would run one at a time.
SelectType=select/cons_tres
SelectTypeParameters=CR_Core_Memory
DefMemPerCPU=1024
SchedulerType=sched/backfill
# Latency: by default a submitted batch job may wait up to batch_sched_delay=3 s for the
# scheduler, and the backfill pass runs every 30 s. A test cluster has few jobs: schedule now.
SchedulerParameters=batch_sched_delay=0,bf_interval=1
# Finished jobs stay in slurmctld's memory (squeue -t all, scontrol show job) at least this long
# (default here 600 s; Slurm's default is 300 s).
MinJobAge=$min_job_age
MaxArraySize=1001
# A cancelled or timed-out job gets SIGTERM, then SIGKILL 5 s later (default 30 s): quicker tests.
KillWait=5
# A node that was down comes back by itself once its slurmd registers (e.g. after down.sh/up.sh).
ReturnToService=2
# Everything in the state dir.
StateSaveLocation=$state/spool/slurmctld
SlurmdSpoolDir=$state/spool/slurmd
SlurmctldPidFile=$ctld_pid
SlurmdPidFile=$slurmd_pid
SlurmctldLogFile=$logdir/slurmctld.log
SlurmdLogFile=$logdir/slurmd.log
SlurmctldDebug=info
SlurmdDebug=info
$node_line State=UNKNOWN
PartitionName=main Nodes=$node_name Default=YES MaxTime=INFINITE State=UP
EOF
)"
conf_changed=""
if [[ ! -f "$conf" ]] || [[ "$(cat "$conf")" != "$new_conf" ]]; then
  conf_changed=1
  printf '%s\n' "$new_conf" >"$conf.tmp"
  mv "$conf.tmp" "$conf"
fi
export SLURM_CONF="$conf"

# ---------------------------------------------------------------- slurm daemons
if [[ -n "$conf_changed" ]] && { pid_alive slurmd "$slurmd_pid" || pid_alive slurmctld "$ctld_pid"; }; then
  note "slurm.conf changed: restarting slurmd and slurmctld"
  stop_daemon slurmd "$slurmd_pid"
  stop_daemon slurmctld "$ctld_pid"
fi

# Marks the daemons' environment (inherited by the slurmstepd processes slurmd forks), so that
# down.sh can find step daemons of this state dir that outlive slurmd.
export TALUS_SLURM_STATE_DIR="$state"

if pid_alive slurmctld "$ctld_pid"; then
  note "slurmctld already running (pid $(pid_of "$ctld_pid"))"
else
  rm -f "$ctld_pid"
  note "starting slurmctld"
  # -c: start from a clean state (no jobs or node state of a previous run), so every up after a
  # down is the same fresh cluster and job ids start again at 1.
  slurmctld -f "$conf" -c \
    || { tail -n 20 "$logdir/slurmctld.log" >&2 || true; die "slurmctld did not start (log: $logdir/slurmctld.log)"; }
fi
if pid_alive slurmd "$slurmd_pid"; then
  note "slurmd already running (pid $(pid_of "$slurmd_pid"))"
else
  rm -f "$slurmd_pid"
  note "starting slurmd"
  slurmd -f "$conf" \
    || { tail -n 20 "$logdir/slurmd.log" >&2 || true; die "slurmd did not start (log: $logdir/slurmd.log)"; }
fi

# ---------------------------------------------------------------- wait for the node
# Up = slurmctld answers and the node takes jobs: idle, or mixed/allocated/completing when up.sh
# runs again while jobs are running.
start=$SECONDS
node_state=""
while :; do
  node_state="$(sinfo -h -N -n "$node_name" -o '%T' 2>/dev/null | head -n 1 || true)"
  case "$node_state" in
    idle | mixed | allocated | completing) break ;;
  esac
  for d in slurmctld:"$ctld_pid" slurmd:"$slurmd_pid"; do
    if ! pid_alive "${d%%:*}" "${d#*:}"; then
      tail -n 20 "$logdir/${d%%:*}.log" >&2 || true
      die "${d%%:*} exited during start-up (log: $logdir/${d%%:*}.log)"
    fi
  done
  if ((SECONDS - start >= timeout)); then
    sinfo -R >&2 || true
    tail -n 20 "$logdir/slurmctld.log" >&2 || true
    die "node $node_name not idle after ${timeout}s (state: '${node_state:-no answer from slurmctld}'; logs in $logdir)"
  fi
  sleep 0.5
done
note "cluster up: node $node_name is $node_state ($(sinfo -h -o '%c CPUs, %m MB' | head -n 1)) after $((SECONDS - start))s"

printf 'export SLURM_CONF=%q\n' "$conf" >"$state/env.sh"
cat "$state/env.sh"
