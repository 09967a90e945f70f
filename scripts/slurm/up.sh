#!/usr/bin/env bash
# Brings up a Slurm cluster on this machine for talus's tests, idempotently: one node, or with
# TALUS_SLURM_NODES=N (N >= 2) N nodes node1..nodeN, N slurmd daemons of this machine in Slurm's
# multiple-slurmd mode (its CPUs and memory split between them; see common.sh):
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
#   TALUS_SLURMD_PORT     slurmd port (default 6818); node i of several listens on this + i - 1
#   TALUS_SLURM_NODES     number of slurmd nodes (default 1)
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

# The nodes: this host (one node), or node1..nodeN, each its slurmd's pid file, log and port.
if ((slurm_nodes == 1)); then
  nodes=("$node_name")
else
  mapfile -t nodes < <(node_names)
fi
pid_file_of() { if ((slurm_nodes == 1)); then echo "$slurmd_pid"; else slurmd_pid_of "$1"; fi; }
log_of() { if ((slurm_nodes == 1)); then echo "$logdir/slurmd.log"; else slurmd_log_of "$1"; fi; }
any_slurmd_alive() {
  local n
  for n in "${nodes[@]}"; do pid_alive slurmd "$(pid_file_of "$n")" && return 0; done
  return 1
}

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
slurmd_ports=()
if ! pid_alive slurmctld "$ctld_pid" && ! any_slurmd_alive; then
  if [[ -z "${TALUS_SLURMCTLD_PORT:-}" ]] && port_busy "$ctld_port"; then
    old="$ctld_port"; ctld_port="$(free_port)"
    note "port $old is taken (another Slurm?): slurmctld listens on $ctld_port instead"
  fi
  if [[ -z "${TALUS_SLURMD_PORT:-}" ]] && port_busy "$slurmd_port"; then
    old="$slurmd_port"; slurmd_port="$(free_port)"
    while [[ "$slurmd_port" == "$ctld_port" ]]; do slurmd_port="$(free_port)"; done
    note "port $old is taken (another Slurm?): slurmd listens on $slurmd_port instead"
  fi
  # Several nodes: the ports after slurmd_port, or free ones (as above) when one is taken.
  slurmd_ports=()
  for ((i = 0; i < slurm_nodes; i++)); do
    p=$((slurmd_port + i))
    if ((i > 0)) && [[ -z "${TALUS_SLURMD_PORT:-}" ]] && port_busy "$p"; then
      p="$(free_port)"
      while [[ " $ctld_port ${slurmd_ports[*]} " == *" $p "* ]]; do p="$(free_port)"; done
      note "port $((slurmd_port + i)) is taken: slurmd of node$((i + 1)) listens on $p instead"
    fi
    slurmd_ports+=("$p")
  done
elif [[ -f "${conf:-}" ]]; then
  # Our daemons run: keep the ports they were started with.
  ctld_port="$(sed -n 's/^SlurmctldPort=//p' "$conf" | head -n 1)"
  slurmd_port="$(sed -n 's/^SlurmdPort=//p' "$conf" | head -n 1)"
  mapfile -t slurmd_ports < <(sed -n -E 's/^NodeName=.* Port=([0-9]+).*/\1/p' "$conf")
  ((${#slurmd_ports[@]} == slurm_nodes)) || slurmd_ports=()
fi
# A cluster of this state dir that runs with another number of nodes: fresh ports for all.
if ((slurm_nodes > 1 && ${#slurmd_ports[@]} != slurm_nodes)); then
  slurmd_ports=()
  for ((i = 0; i < slurm_nodes; i++)); do slurmd_ports+=("$((slurmd_port + i))"); done
fi

# The slurmd settings and node lines of slurm.conf. One node: slurmd -C's line, as it is. Several:
# each node gets an equal share of the CPUs (at least 1) and of the memory, and its own port;
# %n in the file names is the node's name (slurmd replaces it). SlurmdTimeout=10 (default 300):
# a node whose slurmd is killed is DOWN, and its jobs requeued, about 30 s later, not 5 min.
# cred_expire=15 (default 120): a requeued job may start again cred_expire + 1 s after the requeue
# (Reason=BeginTime); 121 s with the default. It is also the lifetime of a job's credential, the
# time a launch may take: 15 s is ample on an idle machine.
auth_extra=""
if ((slurm_nodes == 1)); then
  slurmd_conf="SlurmdSpoolDir=$state/spool/slurmd
SlurmctldPidFile=$ctld_pid
SlurmdPidFile=$slurmd_pid
SlurmctldLogFile=$logdir/slurmctld.log
SlurmdLogFile=$logdir/slurmd.log"
  node_conf="$node_line State=UNKNOWN
PartitionName=main Nodes=$node_name Default=YES MaxTime=INFINITE State=UP"
else
  cpus="$(sed -E 's/.* CPUs=([0-9]+).*/\1/' <<<"$node_line")"
  mem="$(sed -E 's/.* RealMemory=([0-9]+).*/\1/' <<<"$node_line")"
  [[ "$cpus" =~ ^[0-9]+$ && "$mem" =~ ^[0-9]+$ ]] || die "cannot read CPUs and RealMemory from: $node_line"
  node_cpus=$((cpus / slurm_nodes)); ((node_cpus >= 1)) || node_cpus=1
  node_mem=$((mem / slurm_nodes))
  slurmd_conf="SlurmdSpoolDir=$state/spool/slurmd-%n
SlurmctldPidFile=$ctld_pid
SlurmdPidFile=$(slurmd_pid_of %n)
SlurmctldLogFile=$logdir/slurmctld.log
SlurmdLogFile=$(slurmd_log_of %n)
SlurmdTimeout=10"
  auth_extra=",cred_expire=15"
  node_conf=""
  for ((i = 0; i < slurm_nodes; i++)); do
    node_conf+="NodeName=${nodes[i]} NodeHostname=$node_name Port=${slurmd_ports[i]} CPUs=$node_cpus RealMemory=$node_mem State=UNKNOWN
"
  done
  node_conf+="PartitionName=main Nodes=$(IFS=,; echo "${nodes[*]}") Default=YES MaxTime=INFINITE State=UP"
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
AuthInfo=socket=$munge_socket$auth_extra
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
$slurmd_conf
SlurmctldDebug=info
SlurmdDebug=info
$node_conf
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
if [[ -n "$conf_changed" ]] && { [[ -n "$(all_slurmd_pids)" ]] || pid_alive slurmctld "$ctld_pid"; }; then
  note "slurm.conf changed: restarting slurmd and slurmctld"
  # Every slurmd of the state dir, also those of a cluster with another number of nodes.
  for f in $(all_slurmd_pids); do stop_daemon slurmd "$f"; done
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
for n in "${nodes[@]}"; do
  pf="$(pid_file_of "$n")"
  what="slurmd"
  ((slurm_nodes == 1)) || what="slurmd of $n"
  if pid_alive slurmd "$pf"; then
    note "$what already running (pid $(pid_of "$pf"))"
  else
    rm -f "$pf"
    if ((slurm_nodes == 1)); then
      note "starting slurmd"
      slurmd -f "$conf" \
        || { tail -n 20 "$(log_of "$n")" >&2 || true; die "slurmd did not start (log: $(log_of "$n"))"; }
    else
      note "starting slurmd of $n"
      mkdir -p "$state/spool/slurmd-$n"
      # -N: this slurmd is node $n (multiple-slurmd mode). Every node but the first runs in a UTS
      # namespace of its own whose host name is "<host>-<node>", so that its jobs see another
      # host, as on a real cluster: talus cannot check the pids of another host's claims.
      if [[ "$n" == "${nodes[0]}" ]]; then
        slurmd -f "$conf" -N "$n" \
          || { tail -n 20 "$(log_of "$n")" >&2 || true; die "slurmd of $n did not start (log: $(log_of "$n"))"; }
      else
        # shellcheck disable=SC2016 # the positional parameters are the inner shell's
        unshare --uts sh -c 'hostname "$1" && exec slurmd -f "$2" -N "$3"' sh "$(hostname)-$n" "$conf" "$n" \
          || { tail -n 20 "$(log_of "$n")" >&2 || true; die "slurmd of $n did not start in a UTS namespace of its own (log: $(log_of "$n"))"; }
      fi
    fi
  fi
done

# ---------------------------------------------------------------- wait for the nodes
# Up = slurmctld answers and every node takes jobs: idle, or mixed/allocated/completing when
# up.sh runs again while jobs are running.
start=$SECONDS
for n in "${nodes[@]}"; do
  node_state=""
  while :; do
    node_state="$(sinfo -h -N -n "$n" -o '%T' 2>/dev/null | head -n 1 || true)"
    case "$node_state" in
      idle | mixed | allocated | completing) break ;;
    esac
    if ! pid_alive slurmctld "$ctld_pid"; then
      tail -n 20 "$logdir/slurmctld.log" >&2 || true
      die "slurmctld exited during start-up (log: $logdir/slurmctld.log)"
    fi
    if ! pid_alive slurmd "$(pid_file_of "$n")"; then
      tail -n 20 "$(log_of "$n")" >&2 || true
      die "slurmd exited during start-up (log: $(log_of "$n"))"
    fi
    if ((SECONDS - start >= timeout)); then
      sinfo -R >&2 || true
      tail -n 20 "$logdir/slurmctld.log" >&2 || true
      die "node $n not idle after ${timeout}s (state: '${node_state:-no answer from slurmctld}'; logs in $logdir)"
    fi
    sleep 0.5
  done
  if ((slurm_nodes == 1)); then
    note "cluster up: node $n is $node_state ($(sinfo -h -o '%c CPUs, %m MB' | head -n 1)) after $((SECONDS - start))s"
  else
    note "node $n is $node_state ($(sinfo -h -N -n "$n" -o '%c CPUs, %m MB' | head -n 1)) after $((SECONDS - start))s"
  fi
done
((slurm_nodes == 1)) || note "cluster up: ${#nodes[@]} nodes (${nodes[*]}), multiple-slurmd mode"

printf 'export SLURM_CONF=%q\n' "$conf" >"$state/env.sh"
cat "$state/env.sh"
