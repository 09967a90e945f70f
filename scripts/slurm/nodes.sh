#!/usr/bin/env bash
# The Slurm executor on a real multi-node Slurm (issue 47): up.sh with TALUS_SLURM_NODES=2 starts
# two slurmd nodes on this machine (node1, node2: Slurm's multiple-slurmd mode, one CPU and half
# the memory each, DIR shared since they share the file system), then the St Leonards campaign:
#   1. a local run, the reference;
#   2. `--executor slurm --wait` across both nodes, each survey tiled in parts and each pair's
#      m3c2.laz written in segments: every output identical to the local run's (same_outputs.py),
#      and Slurm's job-completion log must show tasks on both nodes;
#   3. a node killed mid-task, Slurm requeues: a second Slurm run; when one of its M3C2 tasks is
#      in the middle of a unit (it holds the unit's claim, the unit is not done), that node's
#      slurmd, its slurmstepd processes and their job processes (the talus task) are SIGKILLed.
#      slurmctld marks the node DOWN (SlurmdTimeout) and requeues the task (JobRequeue, Slurm's
#      default); it runs again on the other node — another host name (up.sh) — takes over the
#      dead task's claim (a later attempt of the same task: `store::Store::claim_attempt`) and
#      the run (still in `--wait`) ends with exit 0 and the local run's outputs. The node is
#      restarted;
#   4. a node killed mid-task, no requeue: the same with `--slurm-args=--no-requeue`: the task
#      ends NODE_FAIL, the run fails naming it, and the same command with `--resume` drops the
#      dead task's claim (Slurm says its jobs have ended: `exec::slurm::check_idle`), submits
#      only what is missing and ends with the local run's outputs.
# Prints the tasks per node of each run, what was killed, what Slurm requeued and what --resume
# submitted. Stops the daemons it started (down.sh) on any exit. Fails loudly, never skips.
#
#   TALUS_BIN=target/release/talus bash scripts/slurm/nodes.sh
#   bash scripts/slurm/nodes.sh      # builds talus (release) in cargo's target dir
#
# Its own state dir (SLURM_STATE_DIR, default /tmp/talus-slurm-nodes), so it never meets the
# one-node cluster of campaign.sh / selftest.sh (/tmp/talus-slurm); ports are picked as up.sh does.
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
repo="$(cd "$here/../.." && pwd)"
export SLURM_STATE_DIR="${SLURM_STATE_DIR:-/tmp/talus-slurm-nodes}"
export TALUS_SLURM_NODES="${TALUS_SLURM_NODES:-2}"
# shellcheck source=common.sh
source "$here/common.sh"
test_name="slurm nodes test"
# shellcheck source=run_test.sh
source "$here/run_test.sh"
indent() { sed 's/^/  /'; }
# Every run writes each pair's m3c2.laz (`--pair-clouds`): where a survey is tiled in parts, its
# pairs' m3c2.laz is written in segments on both nodes and joined, and compared byte for byte.
campaign() { "$talus" campaign "${surveys[@]}" --pair-clouds "$@"; }

((slurm_nodes >= 2)) || fail "TALUS_SLURM_NODES=$slurm_nodes: this test needs at least 2 nodes"
test_inputs

# ---------------------------------------------------------------- cluster
mapfile -t nodes < <(node_names)
started_here=""
pid_alive slurmctld "$ctld_pid" && pid_alive munged "$munged_pid" || started_here=1
for n in "${nodes[@]}"; do pid_alive slurmd "$(slurmd_pid_of "$n")" || started_here=1; done
trap 'teardown_on_exit "slurm nodes test (work: ${work:-})" "$started_here"' EXIT
section "cluster (up.sh, TALUS_SLURM_NODES=$slurm_nodes)"
eval "$(bash "$here/up.sh")" || fail "up.sh could not bring up Slurm"
[[ -n "${SLURM_CONF:-}" ]] || fail "up.sh did not print SLURM_CONF"
config="$(scontrol show config)"
grep -q '^MULTIPLE_SLURMD *= *Yes' <<<"$config" \
  || fail "this slurmctld was not built with --enable-multiple-slurmd (scontrol show config)"
sinfo -N -o '%N %T %c %m'
[[ "$(sinfo -h -N -t idle,mixed,allocated -o %N | sort -u | wc -l)" == "$slurm_nodes" ]] \
  || fail "not all $slurm_nodes nodes take jobs"

# README.md "Where the store meets a network file system" says the store needs no file locks (no
# NFS lock manager): its claims and its lock are link(2)/rename(2) owner files. Hold it to that.
locks="$(grep -rnE '\b(flock|lockf|F_SETLKW?|F_OFD_SETLKW?)\b|fs2::|fd_lock' "$repo/store/src" || true)"
[[ -z "$locks" ]] || fail "the store now takes file locks; README.md's NFS section no longer holds: $locks"

work_in nodes-test
# per_node JOBS: from Slurm's job-completion log, every task of the arrays listed in JOBS (talus's
# stdout: stage, array id, tasks) as "node state count", one line per node and final state.
per_node() {
  awk 'NR == FNR { ids[$2] = 1; next }
       { a = ""; n = ""; s = ""
         for (i = 1; i <= NF; i++) {
           if ($i ~ /^ArrayJobId=/) a = substr($i, 12)
           else if ($i ~ /^NodeList=/) n = substr($i, 10)
           else if ($i ~ /^JobState=/) s = substr($i, 10)
         }
         if (a in ids) c[n " " s]++ }
       END { for (k in c) print k, c[k] }' "$1" "$jobcomp_log" | sort
}
# show_per_node JOBS: per_node, printed; fails unless every node completed at least one task.
show_per_node() {
  local counts n
  counts="$(per_node "$1")"
  echo "tasks per node (Slurm's job-completion log, $jobcomp_log):"
  indent <<<"$counts"
  for n in "${nodes[@]}"; do
    grep -q "^$n COMPLETED " <<<"$counts" || fail "no task of this run completed on $n"
  done
}
# jobcomp_of ARRAY TASK: the job-completion lines of one array task (every attempt), short.
jobcomp_of() {
  grep " ArrayJobId=$1 ArrayTaskId=$2 " "$jobcomp_log" \
    | sed -E 's/.*(JobId=[0-9]+).*(JobState=[A-Z_]+).*(StartTime=[^ ]+).*(EndTime=[^ ]+).*(NodeList=[^ ]+).*/\1 \2 \5 \3 \4/' || true
}

# ---------------------------------------------------------------- 1. local
local_reference

# ---------------------------------------------------------------- 2. slurm --wait on both nodes
section "2. --executor slurm --wait across ${nodes[*]}, each survey tiled in parts"
t0=$SECONDS
rc=0
# Each survey (91k to 181k points) tiled by 3 to 5 units of at most 40,000 points (22 in all),
# spread over the nodes; the local reference tiled each whole: the outputs must be the same bytes.
campaign --out "$work/slurm" --executor slurm --wait --tiling-part 40000 \
  >"$work/slurm.jobs" 2>"$work/slurm.err" || rc=$?
sed 's/^/  /' "$work/slurm.err"
[[ $rc == 0 ]] || fail "the Slurm run exited $rc"
# Eleven arrays and the publishing job; the stages of one unit a task that no array waiting
# for their hosts would wait on (orient, stable, events, points, outputs, campaign) computed at
# the ends of the arrays holding what they read (exec::slurm::Tail).
expected="tiling align aligned field thinned m3c2 sampled kept series volumes segments publish "
[[ "$(cut -d' ' -f1 "$work/slurm.jobs" | tr '\n' ' ')" == "$expected" ]] \
  || fail "expected the arrays $expected: $(cut -d' ' -f1 "$work/slurm.jobs" | tr '\n' ' ')"
echo "Slurm run: $((SECONDS - t0)) s"
show_per_node "$work/slurm.jobs"
! per_node "$work/slurm.jobs" | grep -v ' COMPLETED ' || fail "a task of the Slurm run did not complete"
same_as_local slurm
[[ "$(ls "$work/slurm/.talus/units/tiling" | wc -l)" == 22 ]] \
  || fail "the Slurm run did not tile its surveys in parts: $(ls "$work/slurm/.talus/units/tiling")"
segments="$(ls "$work/slurm/.talus/units/segments" | wc -l)"
((segments > 5)) || fail "the Slurm run wrote its pairs' m3c2.laz in $segments segments"
sampled="$(ls "$work/slurm/.talus/units/sampled" | wc -l)"
kept="$(ls "$work/slurm/.talus/units/kept" | wc -l)"
((sampled == segments && kept == segments)) \
  || fail "the stable ground in $sampled ranges, the events' filter in $kept, m3c2.laz in $segments"
echo "the surveys tiled in 22 parts; the pairs' stable ground and events' filter in $sampled ranges each, m3c2.laz in $segments segments"

# kill_mid_task NAME: run the campaign into $work/NAME with --wait in the background (extra
# options after NAME), catch an M3C2 task in the middle of a unit (freeze_claimer.py), SIGKILL its
# node (slurmd, the node's slurmstepd processes and all their descendants). Sets victim (node),
# m (the m3c2 array), k (the task), unit, claim_host (the host name in the unit's claim),
# killed_at (SECONDS), waiter (pid of the background run, whose exit code goes to $work/NAME.rc).
kill_mid_task() {
  local name="$1" i caught pid stepds all s d sd_pid pids
  shift
  (
    rc=0
    campaign --out "$work/$name" --executor slurm --wait "$@" >"$work/$name.jobs" 2>"$work/$name.err" || rc=$?
    echo "$rc" >"$work/$name.rc"
  ) &
  waiter=$!
  caught="$(python3 "$here/freeze_claimer.py" "$work/$name" m3c2 300)" \
    || fail "no M3C2 task of run '$name' was caught in the middle of a unit"
  read -r pid task_name unit <<<"$caught"
  m="${task_name%_*}"
  k="${task_name#*_}"
  # The node whose slurmstepd has the stopped talus process among its descendants.
  victim=""
  for n in "${nodes[@]}"; do
    for s in $(stepds_of "$(slurmd_log_of "$n")"); do
      if descendants "$s" | grep -x "$pid" >/dev/null; then victim="$n"; stepds="$(stepds_of "$(slurmd_log_of "$n")" | tr '\n' ' ')"; fi
    done
  done
  [[ -n "$victim" ]] || { kill -CONT "$pid" || true; fail "talus task pid $pid (m3c2 $task_name) is under no node's slurmstepd"; }
  [[ "$(squeue -h -j "$task_name" -o %N)" == "$victim" ]] || fail "squeue does not place $task_name on $victim"
  sd_pid="$(pid_of "$(slurmd_pid_of "$victim")")"
  all="$sd_pid $stepds"
  for s in $stepds; do all+=" $(descendants "$s" | tr '\n' ' ')"; done
  echo "caught m3c2 task $k ($task_name) on $victim in the middle of unit $unit: talus pid $pid stopped (SIGSTOP)"
  claim_text="$(tr -s '\n ' ' ' <"$(compgen -G "$work/$name/.talus/claims/*/m3c2/$unit")")"
  claim_host="$(sed -n -E 's/.*"host": "([^"]+)".*/\1/p' <<<"$claim_text")"
  echo "its unit's claim: $claim_text"
  echo "SIGKILL to $victim: its slurmd, its slurmstepd processes and their descendants:"
  # shellcheck disable=SC2086
  read -ra pids <<<"$all"
  all="${pids[*]}"
  ps -o pid=,stat=,args= -p "${all// /,}" | sed 's/^/  /'
  # shellcheck disable=SC2086
  kill -KILL $all
  killed_at=$SECONDS
  for d in $all; do
    for ((i = 0; i < 50; i++)); do [[ -e /proc/$d ]] || break; sleep 0.1; done
    [[ ! -e /proc/$d ]] || fail "pid $d survived SIGKILL"
  done
  [[ ! -d "$work/$name/.talus/units/m3c2/$unit" ]] || fail "unit $unit was done: the kill did not catch it mid-way"
  echo "killed: $(wc -w <<<"$all") processes; unit $unit not done, its claim left behind (pid $pid, dead)"
}

# follow NAME: until the background run ends, print the changes of the victim node's state and of
# the killed task's state (from the kill on); then the run's stderr. Sets rc.
follow() {
  local name="$1" last="" now
  while kill -0 "$waiter" 2>/dev/null; do
    now="$victim: $(sinfo -h -N -n "$victim" -o %T 2>/dev/null || true); ${m}_$k: $(squeue -h -t all -j "${m}_$k" -o '%T %R' 2>/dev/null || echo 'not listed')"
    if [[ "$now" != "$last" ]]; then
      echo "  +$((SECONDS - killed_at)) s  $now"
      last="$now"
    fi
    sleep 0.5
  done
  wait "$waiter" || true
  rc="$(cat "$work/$name.rc")"
  echo "the run with --wait exited $rc, $((SECONDS - killed_at)) s after the kill; its stderr:"
  sed 's/^/  /' "$work/$name.err"
}

# restart_node: the killed node's slurmd again (up.sh starts what is not running); it comes back
# by itself (ReturnToService=2).
restart_node() {
  local t=$SECONDS
  bash "$here/up.sh" >/dev/null 2>"$work/up-again.err" || { cat "$work/up-again.err"; fail "up.sh could not restart $victim"; }
  echo "$victim restarted (up.sh): $(sinfo -h -N -n "$victim" -o %T) after $((SECONDS - t)) s"
}

# ---------------------------------------------------------------- 3. kill a node; Slurm requeues
section "3. a node killed mid-task; Slurm requeues the task"
t0=$SECONDS
kill_mid_task requeue
follow requeue
[[ $rc == 0 ]] || fail "the run whose node was killed exited $rc (Slurm should have requeued the task)"
echo "Slurm's records of m3c2 task $k (every attempt):"
recs="$(jobcomp_of "$m" "$k")"
indent <<<"$recs"
grep -q "JobState=NODE_FAIL NodeList=$victim " <<<"$recs" || fail "no NODE_FAIL record of ${m}_$k on $victim"
grep -q "JobState=COMPLETED " <<<"$recs" || fail "no COMPLETED record of ${m}_$k after the requeue"
again_on="$(sed -n -E 's/.*JobState=COMPLETED NodeList=([^ ]+).*/\1/p' <<<"$recs")"
job_text="$(scontrol show job "${m}_$k")"
restarts="$(sed -n -E 's/.*Restarts=([0-9]+).*/\1/p' <<<"$job_text")"
report="$(tr -s '\n ' ' ' <"$work/requeue/.talus/slurm/1/tasks/m3c2-$k.json")"
echo "resubmitted: Slurm requeued ${m}_$k (Restarts=$restarts); it ran again on $again_on and took over"
echo "the dead task's claim; its task report: $report"
grep -q '"computed": 1' <<<"$report" || fail "the requeued task did not compute unit $unit itself"
# Every node has a host name of its own (up.sh): the claim it took over was another host's, whose
# pid it could not check — a later attempt of the same task takes over an earlier one's claims.
again_host="$(sed -n -E 's/.*"host": "([^"]+)".*/\1/p' <<<"$report")"
[[ -n "$claim_host" && "$again_host" != "$claim_host" ]] \
  || fail "the requeued task ran on host '$again_host', the dead claim's host is '$claim_host': not a take-over across hosts"
echo "across hosts: the claim of $claim_host taken over on $again_host"
[[ "${restarts:-0}" -ge 1 ]] || fail "scontrol shows Restarts=${restarts:-?} for ${m}_$k"
[[ "$again_on" != "$victim" ]] || fail "the requeued task ran on the killed node $victim"
[[ -d "$work/requeue/.talus/units/m3c2/$unit" ]] || fail "unit $unit is not done after the requeue"
show_per_node "$work/requeue.jobs"
"$talus" status "$work/requeue" | tail -n 3
same_as_local requeue
echo "kill and requeue: $((SECONDS - t0)) s"
restart_node

# ---------------------------------------------------------------- 4. kill a node; no requeue; --resume
section "4. a node killed mid-task with --no-requeue; --resume"
t0=$SECONDS
kill_mid_task noreq --slurm-args=--no-requeue
follow noreq
[[ "$rc" != 0 ]] || fail "a run whose task's node was killed (no requeue) exited 0"
grep -q "m3c2 task $k (${m}_$k, job [0-9]*): NODE_FAIL" "$work/noreq.err" \
  || fail "--wait did not name m3c2 task $k as NODE_FAIL"
echo "Slurm's records of m3c2 task $k:"
jobcomp_of "$m" "$k" | sed 's/^/  /'
restart_node
echo "talus status after the failed run:"
"$talus" status "$work/noreq" | sed 's/^/  /' | tee "$work/status-noreq.txt"
grep -q "m3c2 task $k (${m}_$k, job [0-9]*): NODE_FAIL" "$work/status-noreq.txt" \
  || fail "talus status does not name m3c2 task $k as NODE_FAIL"
echo
echo "the same command with --resume:"
ntasks="$(awk '$1 == "m3c2" { print $3 }' "$work/noreq.jobs")"
rc=0
campaign --out "$work/noreq" --executor slurm --wait --slurm-args=--no-requeue --resume \
  >"$work/resume.jobs" 2>"$work/resume.err" || rc=$?
echo "job arrays submitted (stage, job id, tasks):"
sed 's/^/  /' "$work/resume.jobs"
sed 's/^/  /' "$work/resume.err"
[[ $rc == 0 ]] || fail "the resumed run exited $rc"
# The killed task's claim (on host $claim_host) is dropped once Slurm says the submission's jobs
# have all ended, not left to hold for the store's lease.
grep -q "1 claim(s) left by ended tasks of submission 1 dropped" "$work/resume.err" \
  || fail "--resume did not drop the claim the killed task left on $claim_host"
! grep -q '^tiling ' "$work/resume.jobs" || fail "--resume submitted the tiling again"
resumed_m3c2="$(awk '$1 == "m3c2" { print $3 }' "$work/resume.jobs")"
[[ -n "$resumed_m3c2" && "$resumed_m3c2" -lt "$ntasks" ]] \
  || fail "--resume submitted ${resumed_m3c2:-no} M3C2 task(s) of $ntasks, expected only the missing ones"
echo "resubmitted by --resume: $(awk '{ printf "%s%s %s", sep, $1, $3; sep = ", " }' "$work/resume.jobs") (task counts)"
echo "the resumed run's tasks:"
show_per_node "$work/resume.jobs"
[[ -d "$work/noreq/.talus/units/m3c2/$unit" ]] || fail "unit $unit is not done after --resume"
same_as_local noreq
echo "kill, fail and --resume: $((SECONDS - t0)) s"

echo
echo "slurm nodes test: passed ($slurm_nodes nodes; identical outputs across nodes, after a node killed and requeued, and after a node killed and --resume)"
