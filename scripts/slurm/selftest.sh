#!/usr/bin/env bash
# Self-test of the one-node Slurm cluster (up.sh/down.sh): brings it up, proves each feature that
# talus's Slurm back end will rely on, with a check that fails loudly, and tears it down again
# (down.sh runs on any exit, also on failure). Takes about 1.5-2 minutes, most of it waiting for
# the 1-minute time limit of (e), which runs while the other checks run on the second core.
#
#   (a) job array: one file per SLURM_ARRAY_TASK_ID in a shared dir; two 1-CPU tasks at once
#   (b) afterok on the whole array (runs only after every task succeeded); aftercorr task by task
#   (c) afterok on an array with a failing task, with and without --kill-on-invalid-dep=yes
#   (d) scancel of one running array task; what squeue/scontrol/sacct say afterwards
#   (e) --time=0:01 limit -> TIMEOUT
#   (f) --mem: checked at submission and for scheduling; enforced at run time or not
#   (g) latency from sbatch to completion of a trivial job
#   (h) sbatch --wait (exit code, duration) and polling with squeue
#
# Uses $SLURM_STATE_DIR like up.sh (default /tmp/talus-slurm); the test's files go to
# $SLURM_STATE_DIR/selftest. A cluster already up in that state dir is reused and then stopped.
# Ends with "selftest: N passed, 0 failed" or exits non-zero at the first failed check.
# shellcheck disable=SC2016 # the single-quoted --wrap scripts expand their variables in the job
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
# shellcheck source=common.sh
source "$here/common.sh"

passed=0
ok() { passed=$((passed + 1)); echo "  PASS: $*"; }
fail() {
  echo "" >&2
  echo "******** selftest FAILED: $* ********" >&2
  exit 1
}
say() { echo "  $*"; }
section() { echo; echo "== $*"; }

# Always tear down, also when a check fails (set -e or fail): nothing may be left running.
trap 'teardown_on_exit selftest 1' EXIT

section "up.sh"
eval "$(bash "$here/up.sh")"
[[ "${SLURM_CONF:-}" == "$conf" ]] || fail "up.sh did not print export SLURM_CONF=$conf"
ok "cluster up, SLURM_CONF=$SLURM_CONF"
sinfo

work="$state/selftest"
rm -rf "$work"
mkdir -p "$work"
cd "$work"

# ---------------------------------------------------------------- helpers
# State of one job or array task (e.g. 12 or 12_3). -t all: without it squeue shows nothing for
# a finished job (it lists only pending/running ones by default).
jstate() { squeue -h -t all -j "$1" -o '%T' 2>/dev/null | head -n 1; }
jreason() { squeue -h -t all -j "$1" -o '%r' 2>/dev/null | head -n 1; }
# One "TASKID STATE" line per task of array $1 (-r: pending tasks one per line too).
tasks() { squeue -h -t all -r -j "$1" -o '%K %T' 2>/dev/null | sort -n; }
is_final() {
  case "$1" in
    COMPLETED | FAILED | CANCELLED | TIMEOUT | OUT_OF_MEMORY | NODE_FAIL | PREEMPTED | BOOT_FAIL | DEADLINE) return 0 ;;
  esac
  return 1
}
# wait_final ID SECONDS: until every job/task of ID is in a final state.
wait_final() {
  local id="$1" limit="$2" start=$SECONDS s all
  while :; do
    all=1
    while read -r s; do is_final "$s" || all=""; done < <(squeue -h -t all -r -j "$id" -o '%T' 2>/dev/null)
    [[ -n "$all" ]] && return 0
    ((SECONDS - start < limit)) || fail "job $id not finished after ${limit}s: $(squeue -h -t all -r -j "$id" -o '%i=%T(%r)' | tr '\n' ' ')"
    sleep 0.2
  done
}
# wait_for ID STATE [REASON] SECONDS
wait_for() {
  local id="$1" want="$2" reason="" limit start=$SECONDS
  if [[ $# == 4 ]]; then reason="$3"; limit="$4"; else limit="$3"; fi
  while :; do
    if [[ "$(jstate "$id")" == "$want" ]] && { [[ -z "$reason" ]] || [[ "$(jreason "$id")" == "$reason" ]]; }; then
      return 0
    fi
    ((SECONDS - start < limit)) || fail "job $id: wanted $want${reason:+ ($reason)} within ${limit}s, is $(jstate "$id") ($(jreason "$id"))"
    sleep 0.2
  done
}
# scontrol field of one job or task: sfield ID Field
sfield() { scontrol show job -o "$1" | tr ' ' '\n' | sed -n "s/^$2=//p" | head -n 1; }
now() { date +%s.%N; }
secs() { awk -v a="$1" -v b="$2" 'BEGIN { printf "%.2f", b - a }'; }

real_mem="$(sinfo -h -o '%m' | head -n 1 | tr -dc 0-9)"

# ---------------------------------------------------------------- (a) array
section "(a) job array, one file per SLURM_ARRAY_TASK_ID"
mkdir -p a
cat >a/task.sh <<'EOF'
#!/bin/bash
# One talus work unit: writes its own result file, named by the task id, into the shared dir.
set -euo pipefail
start=$(date +%s.%N)
sleep 2
echo "task=$SLURM_ARRAY_TASK_ID array_job=$SLURM_ARRAY_JOB_ID job=$SLURM_JOB_ID start=$start end=$(date +%s.%N)" \
  >"$1/task_$SLURM_ARRAY_TASK_ID.tmp"
mv "$1/task_$SLURM_ARRAY_TASK_ID.tmp" "$1/task_$SLURM_ARRAY_TASK_ID"
EOF
t_submit_a=$(now)
A=$(sbatch --parsable --array=0-3 -J st-a -o "$work/a/%A_%a.out" a/task.sh "$work/a")
say "sbatch --parsable --array=0-3 a/task.sh -> '$A'"
[[ "$A" =~ ^[0-9]+$ ]] || fail "sbatch --parsable printed '$A', not a job id"
# (b) submitted right away, while the array is pending/running: the normal way to chain stages.
cat >a/after.sh <<'EOF'
#!/bin/bash
set -euo pipefail
n=$(ls "$1" | grep -c '^task_[0-9]*$' || true)
echo "files_at_start=$n start=$(date +%s.%N)" >"$1/after"
EOF
B=$(sbatch --parsable --dependency=afterok:"$A" -J st-b -o "$work/a/after.out" a/after.sh "$work/a")
say "sbatch --dependency=afterok:$A -> $B; squeue shows dependency: $(squeue -h -j "$B" -o '%T %r %E')"
# aftercorr: task i of the second array waits for task i of the first only.
cat >a/corr.sh <<'EOF'
#!/bin/bash
set -euo pipefail
test -f "$1/task_$SLURM_ARRAY_TASK_ID" && echo ok >"$1/corr_$SLURM_ARRAY_TASK_ID"
EOF
C=$(sbatch --parsable --array=0-3 --dependency=aftercorr:"$A" -J st-corr -o /dev/null a/corr.sh "$work/a")
squeue -j "$A,$B,$C" -o '%.10i %.8A %.6K %.10T %.20r %E'
wait_final "$A" 60
say "array tasks (squeue -h -t all -j $A -o '%i %A %K %T'):"
squeue -h -t all -r -j "$A" -o '    %i %A %K %T' | sort
for i in 0 1 2 3; do
  [[ -s "a/task_$i" ]] || fail "array task $i wrote no a/task_$i"
  [[ "$(jstate "${A}_$i")" == COMPLETED ]] || fail "array task ${A}_$i is $(jstate "${A}_$i"), not COMPLETED"
done
ok "array $A: 4 tasks COMPLETED, files a/task_0..3 written"
cat a/task_? | sed 's/^/    /'
say "output files from -o %A_%a.out: $(cd a && echo ./*.out)"
# Two tasks ran at once (cons_tres, CR_Core_Memory, DefMemPerCPU): their [start, end] overlap.
overlap=$(awk '{ for (i = 1; i <= NF; i++) { split($i, kv, "="); v[kv[1]] = kv[2] } s[NR] = v["start"]; e[NR] = v["end"] }
  END { n = 0; for (i = 1; i <= NR; i++) for (j = i + 1; j <= NR; j++) if (s[i] < e[j] && s[j] < e[i]) n++; print n }' a/task_?)
[[ "$overlap" -ge 1 ]] || fail "no two array tasks overlapped in time: cons_tres does not run two 1-CPU tasks at once"
ok "two 1-CPU array tasks ran at the same time ($overlap overlapping pairs of 4 tasks of 2 s)"
say "array wall time, submit to last task done: $(secs "$t_submit_a" "$(now)") s"

# ---------------------------------------------------------------- (b) afterok
section "(b) afterok:$A on the whole array"
wait_final "$B" 30
[[ "$(jstate "$B")" == COMPLETED ]] || fail "dependent job $B is $(jstate "$B")"
grep -q '^files_at_start=4 ' a/after || fail "dependent job $B started before all 4 task files existed: $(cat a/after)"
last_end=$(cat a/task_? | sed -E 's/.*end=([0-9.]+).*/\1/' | sort -n | tail -n 1)
b_start=$(sed -E 's/.*start=([0-9.]+).*/\1/' a/after)
ok "job $B ran after the whole array ($(cut -d' ' -f1 a/after)); last task end -> dependent start: $(secs "$last_end" "$b_start") s"
wait_final "$C" 30
for i in 0 1 2 3; do [[ -s "a/corr_$i" ]] || fail "aftercorr task ${C}_$i did not see a/task_$i"; done
ok "aftercorr:$A array $C: each task ran after its own task of $A"

# ---------------------------------------------------------------- (e) TIMEOUT (started now, checked last)
section "(e) --time=0:01 (started now; checked at the end)"
cat >timeout.sh <<'EOF'
#!/bin/bash
# Records the SIGTERM that Slurm sends at the time limit (KillWait later comes SIGKILL).
trap 'echo "SIGTERM at $(date +%s.%N)" >>"$1"; exit 143' TERM
echo "start $(date +%s.%N)" >"$1"
sleep 300 &
wait
EOF
t_submit_e=$(now)
# Submitted through `sbatch --wait` in the background, to see also what --wait returns for a
# TIMEOUT. With --parsable it prints the job id at submission, then waits.
(
  rc=0
  sbatch --wait --parsable --time=0:01 -J st-timeout -o "$work/timeout.out" timeout.sh "$work/timeout.log" \
    >"$work/timeout.id" || rc=$?
  echo "$rc" >"$work/timeout.rc"
) &
e_waiter=$!
for ((i = 0; i < 50; i++)); do
  E=$(tr -dc 0-9 <"$work/timeout.id" 2>/dev/null || true)
  [[ -n "$E" ]] && break
  sleep 0.1
done
[[ -n "$E" ]] || fail "sbatch --wait --parsable printed no job id within 5 s"
say "job $E: TimeLimit as Slurm stores --time=0:01: $(sfield "$E" TimeLimit)"

# ---------------------------------------------------------------- (c) failing task
section "(c) afterok on an array with a failing task"
F=$(sbatch --parsable --array=0-2 -J st-fail -o /dev/null --wrap 'sleep 1; [ "$SLURM_ARRAY_TASK_ID" != 1 ] || exit 3')
F_keep=$(sbatch --parsable --dependency=afterok:"$F" -J st-dep-keep -o /dev/null --wrap true)
F_kill=$(sbatch --parsable --dependency=afterok:"$F" --kill-on-invalid-dep=yes -J st-dep-kill -o /dev/null --wrap true)
F_any=$(sbatch --parsable --dependency=afterany:"$F" -J st-dep-any -o /dev/null --wrap true)
F_not=$(sbatch --parsable --dependency=afternotok:"$F" -J st-dep-notok -o /dev/null --wrap true)
wait_final "$F" 60
tasks "$F" | sed 's/^/    task /'
[[ "$(jstate "${F}_1")" == FAILED ]] || fail "task ${F}_1 (exit 3) is $(jstate "${F}_1"), not FAILED"
say "scontrol for ${F}_1: JobState=$(sfield "${F}_1" JobState) Reason=$(sfield "${F}_1" Reason) ExitCode=$(sfield "${F}_1" ExitCode)"
ok "task exiting 3 -> FAILED, ExitCode $(sfield "${F}_1" ExitCode)"
wait_for "$F_kill" CANCELLED 15
say "afterok + --kill-on-invalid-dep=yes: $(squeue -h -t all -j "$F_kill" -o '%T, Reason=%r, Dependency=%E')"
wait_for "$F_keep" PENDING DependencyNeverSatisfied 15
sleep 2 # and it stays so
[[ "$(jstate "$F_keep")" == PENDING ]] || fail "afterok job $F_keep left PENDING: $(jstate "$F_keep")"
say "afterok without it:            $(squeue -h -t all -j "$F_keep" -o '%T, Reason=%r, Dependency=%E')"
ok "failed task: afterok dependant stays PENDING (DependencyNeverSatisfied), with --kill-on-invalid-dep=yes it is CANCELLED"
wait_final "$F_any" 30
wait_final "$F_not" 30
say "afterany -> $(jstate "$F_any"), afternotok -> $(jstate "$F_not")"
[[ "$(jstate "$F_any")" == COMPLETED && "$(jstate "$F_not")" == COMPLETED ]] || fail "afterany/afternotok did not run"
ok "afterany and afternotok dependants ran"
scancel "$F_keep"

# ---------------------------------------------------------------- (d) scancel one task
section "(d) scancel of one running array task"
D=$(sbatch --parsable --array=0-1 -J st-cancel -o "$work/d_%A_%a.out" --wrap 'if [ "$SLURM_ARRAY_TASK_ID" = 0 ]; then sleep 120; fi')
D_dep=$(sbatch --parsable --dependency=afterok:"$D" -J st-cancel-dep -o /dev/null --wrap true)
wait_for "${D}_0" RUNNING 30
scancel "${D}_0"
say "scancel ${D}_0 while RUNNING"
wait_final "$D" 30
tasks "$D" | sed 's/^/    task /'
[[ "$(jstate "${D}_0")" == CANCELLED ]] || fail "cancelled task ${D}_0 is $(jstate "${D}_0")"
[[ "$(jstate "${D}_1")" == COMPLETED ]] || fail "the other task ${D}_1 is $(jstate "${D}_1")"
say "squeue -t all: $(squeue -h -t all -j "${D}_0" -o '%i %T Reason=%r')"
say "scontrol show job ${D}_0: JobState=$(sfield "${D}_0" JobState) ExitCode=$(sfield "${D}_0" ExitCode)"
say "task's output file: $(tr '\n' ' ' <"$work/d_${D}_0.out")"
ok "cancelled task -> CANCELLED, the rest of the array runs on"
wait_for "$D_dep" PENDING DependencyNeverSatisfied 15
say "afterok:$D after a cancelled task: $(squeue -h -t all -j "$D_dep" -o '%T, Reason=%r, Dependency=%E')"
ok "afterok treats a cancelled task like a failed one (never satisfied)"
scancel "$D_dep"
say "sacct (no accounting storage): $(sacct -j "$D" 2>&1 | head -n 1)"
say "sacct -c (job completion log $jobcomp_log), raw job ids only:"
sacct -c -o jobid,jobname,state,exitcode -j "$(squeue -h -t all -r -j "$D" -o '%A' | tr '\n' ',')" 2>/dev/null | sed 's/^/    /'
grep -q "ArrayJobId=$D ArrayTaskId=0 " "$jobcomp_log" || fail "no line for ${D}_0 in $jobcomp_log"
say "job completion log line (fields): $(grep "ArrayJobId=$D ArrayTaskId=0 " "$jobcomp_log" | tr ' ' '\n' | grep -E '^(JobId|JobState|ArrayJobId|ArrayTaskId|ExitCode)=' | tr '\n' ' ')"
ok "final states readable from squeue -t all, scontrol show job, sacct -c and the completion log"

# ---------------------------------------------------------------- (f) --mem
section "(f) --mem"
out=$(sbatch --parsable --mem=$((real_mem + 1))M -o /dev/null --wrap true 2>&1) && fail "--mem=$((real_mem + 1))M (> RealMemory=$real_mem) was accepted: $out"
say "--mem=$((real_mem + 1))M: $(tr '\n' ' ' <<<"$out")"
ok "--mem above RealMemory is refused at submission"
# Memory is a consumable resource: while (e) holds one core and DefMemPerCPU=1024 MB, a job
# asking for more than the rest waits although a core is free.
big=$((real_mem - 1024 + 1))
M1=$(sbatch --parsable --mem=${big}M -J st-mem-big -o /dev/null --wrap true)
sleep 2
say "job asking --mem=${big}M while (e) holds 1024 MB: $(squeue -h -t all -j "$M1" -o '%T Reason=%r')"
[[ "$(jstate "$M1")" == PENDING && "$(jreason "$M1")" == Resources ]] || fail "job $M1 needing more memory than free is $(jstate "$M1") ($(jreason "$M1"))"
ok "a job whose --mem does not fit next to the running ones waits (Reason=Resources): memory is a scheduled resource"
# Cancel it: pending at the head of the queue it would hold back the smaller jobs below (the
# scheduler does not start lower-priority jobs that would delay it).
scancel "$M1"
# At run time: no cgroup, jobacct_gather/none -> is the limit enforced?
M2=$(sbatch --parsable --mem=50M -J st-mem-over -o "$work/mem.out" --wrap 'echo SLURM_MEM_PER_NODE=$SLURM_MEM_PER_NODE; perl -e '\''$x = "a" x (300*1024*1024); print "allocated ", length($x) >> 20, " MiB\n"'\''')
wait_final "$M2" 30
say "--mem=50M job allocating 300 MiB: $(jstate "$M2"); output: $(tr '\n' ' ' <"$work/mem.out")"
if [[ "$(jstate "$M2")" == COMPLETED ]]; then
  say "=> --mem is NOT enforced at run time here (no cgroup task plugin, no jobacct_gather)"
else
  say "=> --mem IS enforced at run time: $(jstate "$M2")"
fi
ok "--mem run-time behaviour recorded"

# ---------------------------------------------------------------- (g) latency
section "(g) latency, sbatch to COMPLETED, trivial job (polling squeue every 0.1 s)"
lat=()
for i in 1 2 3 4 5; do
  t0=$(now)
  j=$(sbatch --parsable -J st-lat -o /dev/null --wrap true)
  while [[ "$(jstate "$j")" != COMPLETED ]]; do
    (($(awk -v a="$t0" -v b="$(now)" 'BEGIN { print (b - a > 30) }'))) && fail "trivial job $j not COMPLETED after 30 s: $(jstate "$j")"
    sleep 0.1
  done
  lat+=("$(secs "$t0" "$(now)")")
done
say "latencies (s): ${lat[*]}"
ok "trivial jobs complete; max $(printf '%s\n' "${lat[@]}" | sort -n | tail -n 1) s"

# ---------------------------------------------------------------- (h) sbatch --wait
section "(h) sbatch --wait"
t0=$(now)
rc=0
sbatch --wait -J st-wait -o /dev/null --wrap true >/dev/null || rc=$?
say "sbatch --wait --wrap true: rc=$rc after $(secs "$t0" "$(now)") s"
[[ $rc == 0 ]] || fail "sbatch --wait of a successful job returned $rc"
rc=0
sbatch --wait -J st-wait3 -o /dev/null --wrap 'exit 3' >/dev/null || rc=$?
say "sbatch --wait --wrap 'exit 3': rc=$rc"
[[ $rc == 3 ]] || fail "sbatch --wait of a job exiting 3 returned $rc"
rc=0
sbatch --wait --array=0-2 -J st-waitarr -o /dev/null --wrap '[ "$SLURM_ARRAY_TASK_ID" != 1 ] || exit 7' >/dev/null || rc=$?
say "sbatch --wait --array=0-2 (task 1 exits 7): rc=$rc"
[[ $rc == 7 ]] || fail "sbatch --wait of an array with a task exiting 7 returned $rc"
ok "sbatch --wait returns the job's exit code (an array's: the failing task's)"
# A job cancelled while running.
(
  rc=0
  sbatch --wait -J st-waitcancel -o /dev/null --wrap 'sleep 120' >/dev/null || rc=$?
  echo "$rc" >"$work/waitcancel.rc"
) &
waiter=$!
for ((i = 0; i < 100; i++)); do
  W=$(squeue -h -n st-waitcancel -o '%A' | head -n 1)
  [[ -n "$W" && "$(jstate "$W")" == RUNNING ]] && break
  sleep 0.2
done
[[ -n "${W:-}" ]] || fail "sbatch --wait job st-waitcancel never appeared"
scancel "$W"
wait "$waiter" || true
say "sbatch --wait on job $W cancelled while running: rc=$(cat "$work/waitcancel.rc") (job state $(jstate "$W"), ExitCode $(sfield "$W" ExitCode))"
# Seen by hand: 1 usually, but 0 or 143 when the cancel falls just before one of sbatch's polls
# (2 s, 10 s, 42 s, ... after submission): the exit code of --wait does not tell CANCELLED.
[[ "$(cat "$work/waitcancel.rc")" == 0 ]] && say "=> WARNING: sbatch --wait exited 0 for a CANCELLED job"
ok "sbatch --wait on a cancelled job recorded (its exit code is not a reliable state)"
# Polling.
j=$(sbatch --parsable -J st-poll -o /dev/null --wrap 'sleep 1')
seen=""
while :; do
  s=$(squeue -h -j "$j" -o '%T' 2>/dev/null || true)
  [[ -z "$s" ]] && break
  [[ " $seen " == *" $s "* ]] || seen+="$s "
  sleep 0.1
done
say "squeue -h -j $j -o %T while polling: ${seen}then '' (empty) once finished"
say "squeue -h -t all -j $j -o %T afterwards: $(jstate "$j")"
[[ "$(jstate "$j")" == COMPLETED ]] || fail "polled job $j is $(jstate "$j")"
ok "polling: squeue without -t prints nothing for a finished job; with -t all it prints the final state"

# ---------------------------------------------------------------- (e) checked
section "(e) waiting for the --time=0:01 job $E to hit its limit"
wait_final "$E" 150
t_end_e=$(now)
wait "$e_waiter" || true
say "sbatch --wait for the TIMEOUT job returned rc=$(cat "$work/timeout.rc" 2>/dev/null || echo '?') after $(secs "$t_submit_e" "$(now)") s"
say "job $E: $(squeue -h -t all -j "$E" -o '%T Reason=%r') ExitCode=$(sfield "$E" ExitCode) RunTime=$(sfield "$E" RunTime) TimeLimit=$(sfield "$E" TimeLimit)"
say "submit -> TIMEOUT seen: $(secs "$t_submit_e" "$t_end_e") s; job's own log: $(tr '\n' ' ' <"$work/timeout.log")"
say "slurm's message in its output: $(tr '\n' ' ' <"$work/timeout.out")"
[[ "$(jstate "$E")" == TIMEOUT ]] || fail "job $E over its time limit is $(jstate "$E"), not TIMEOUT"
ok "time limit -> TIMEOUT (Reason=TimeLimit)"

section "all test jobs (squeue -t all -o '%i %A %j %T %r')"
squeue -t all -o '%.8i %.6A %.14j %.10T %r' | sed 's/^/  /'

echo
echo "selftest: $passed passed, 0 failed"
