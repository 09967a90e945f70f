#!/usr/bin/env bash
# The Slurm executor against a real Slurm (issue 12): on a one-node cluster (up.sh: installs
# Debian's slurmctld, slurmd, slurm-client and munge when missing), the St Leonards campaign
# (tests/data/st-leonards, six surveys):
#   1. a local run (`talus campaign ...`), the reference;
#   2. `--executor slurm --wait`: every output compared with the local run's, byte for byte
#      (same_outputs.py: all of DIR but .talus/, the run's own timings blanked);
#   3. a second Slurm run, with `--wait` in the background; once its M3C2 array runs, one task is
#      cancelled with scancel while it is queued and one while it runs: the run must fail and
#      say so, `talus status` must name the cancelled tasks, and the same command with `--resume`
#      must submit only what is missing (no tiling, fewer M3C2 tasks) and end with the local
#      run's outputs, byte for byte;
#   4. `--plan-only`: the plan and the sbatch scripts written, nothing submitted.
# Stops the daemons it started (down.sh, by their pid files) on any exit; a cluster that was
# already up is left up. Fails loudly, never skips: without Slurm (not installable, not starting)
# or without the data, it exits non-zero.
#
#   bash scripts/slurm/campaign.sh                   # builds talus (release) in cargo's target dir
#   TALUS_BIN=target/debug/talus bash scripts/slurm/campaign.sh
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
repo="$(cd "$here/../.." && pwd)"
# shellcheck source=common.sh
source "$here/common.sh"
test_name="slurm campaign test"
# shellcheck source=run_test.sh
source "$here/run_test.sh"
test_inputs

# ---------------------------------------------------------------- cluster
started_here=""
if ! pid_alive slurmctld "$ctld_pid" || ! pid_alive slurmd "$slurmd_pid" || ! pid_alive munged "$munged_pid"; then
  started_here=1
fi
# Only a cluster this test started is stopped again (down.sh), on any exit.
trap 'teardown_on_exit "slurm campaign test (work: ${work:-})" "$started_here"' EXIT
section "cluster (up.sh)"
eval "$(bash "$here/up.sh")" || fail "up.sh could not bring up Slurm"
[[ -n "${SLURM_CONF:-}" ]] || fail "up.sh did not print SLURM_CONF"
sinfo

work_in campaign-test

# ---------------------------------------------------------------- 1. local
local_reference

# ---------------------------------------------------------------- 2. slurm --wait
section "2. --executor slurm --wait"
t0=$SECONDS
rc=0
campaign --out "$work/slurm" --executor slurm --wait >"$work/slurm.jobs" 2>"$work/slurm.err" || rc=$?
echo "job arrays submitted (stage, job id, tasks):"
sed 's/^/  /' "$work/slurm.jobs"
sed 's/^/  /' "$work/slurm.err"
[[ $rc == 0 ]] || fail "the Slurm run exited $rc"
# Eight arrays and the publishing job; the stages of one unit a task that no array waiting for
# their hosts would wait on (aligned, orient, events, points, outputs, campaign) computed at the
# ends of the arrays holding what they read (exec::slurm::Tail).
expected="tiling align field thinned m3c2 stable series volumes publish "
[[ "$(cut -d' ' -f1 "$work/slurm.jobs" | tr '\n' ' ')" == "$expected" ]] \
  || fail "expected the arrays $expected: $(cut -d' ' -f1 "$work/slurm.jobs" | tr '\n' ' ')"
echo "Slurm run: $((SECONDS - t0)) s"
same_as_local slurm

# ---------------------------------------------------------------- 3. cancel, then --resume
section "3. a second Slurm run; cancel M3C2 tasks mid-way; --resume"
rc_file="$work/cancel.rc"
(
  rc=0
  campaign --out "$work/cancel" --executor slurm --wait >"$work/cancel.jobs" 2>"$work/cancel.err" || rc=$?
  echo "$rc" >"$rc_file"
) &
waiter=$!
m=""
for ((i = 0; i < 600; i++)); do
  m="$(awk '$1 == "m3c2" { print $2 }' "$work/cancel.jobs" 2>/dev/null || true)"
  [[ -n "$m" ]] && break
  sleep 0.1
done
[[ -n "$m" ]] || fail "the second run printed no m3c2 job id"
ntasks="$(awk '$1 == "m3c2" { print $3 }' "$work/cancel.jobs")"
last=$((ntasks - 1))
for ((i = 0; i < 1200; i++)); do
  [[ "$(squeue -h -t all -j "${m}_0" -o %T 2>/dev/null || true)" == RUNNING ]] && break
  sleep 0.05
done
state0="$(squeue -h -t all -j "${m}_0" -o %T)"
state_last="$(squeue -h -t all -j "${m}_$last" -o %T)"
echo "m3c2 array $m: task 0 is $state0, task $last is $state_last; scancel ${m}_$last ${m}_0"
scancel "${m}_$last" "${m}_0"
wait "$waiter" || true
rc="$(cat "$rc_file")"
echo "the run with --wait exited $rc; its stderr:"
sed 's/^/  /' "$work/cancel.err"
[[ "$rc" != 0 ]] || fail "a run with cancelled tasks exited 0"
grep -q "m3c2 task $last (${m}_$last" "$work/cancel.err" || fail "--wait did not name the cancelled task m3c2 $last"
grep -q "m3c2 task 0 (${m}_0, job [0-9]*): CANCELLED" "$work/cancel.err" || fail "--wait did not name the cancelled task m3c2 0"
echo
echo "talus status after the cancel:"
"$talus" status "$work/cancel" | tee "$work/status-cancel.txt"
# A running task cancelled is CANCELLED in squeue; a queued array task cancelled leaves no record
# at all in Slurm (squeue, scontrol: "not found"; no job-completion line).
grep -q "m3c2 task 0 (${m}_0, job [0-9]*): CANCELLED" "$work/status-cancel.txt" \
  || fail "talus status does not name m3c2 task 0 as CANCELLED"
grep -q "m3c2 task $last (${m}_$last): never ran: cancelled while queued" "$work/status-cancel.txt" \
  || fail "talus status does not name m3c2 task $last as cancelled while queued"
grep -q "cancelled by Slurm because a job they wait for failed" "$work/status-cancel.txt" \
  || fail "talus status does not say the later jobs were cancelled"

echo
echo "the same command with --resume:"
rc=0
campaign --out "$work/cancel" --executor slurm --wait --resume >"$work/resume.jobs" 2>"$work/resume.err" || rc=$?
echo "job arrays submitted (stage, job id, tasks):"
sed 's/^/  /' "$work/resume.jobs"
sed 's/^/  /' "$work/resume.err"
[[ $rc == 0 ]] || fail "the resumed run exited $rc"
! grep -q '^tiling ' "$work/resume.jobs" || fail "--resume submitted the tiling again"
resumed_m3c2="$(awk '$1 == "m3c2" { print $3 }' "$work/resume.jobs")"
[[ -n "$resumed_m3c2" && "$resumed_m3c2" -lt "$ntasks" ]] \
  || fail "--resume submitted ${resumed_m3c2:-no} M3C2 task(s) of $ntasks, expected only the missing ones"
same_as_local cancel

# ---------------------------------------------------------------- 4. --plan-only
section "4. --plan-only"
before="$(squeue -h -t all -o %i | wc -l)"
campaign --out "$work/planonly" --executor slurm --plan-only --slurm-args "--time=30 --comment='talus test'" \
  >"$work/planonly.out" 2>"$work/planonly.err" || { cat "$work/planonly.err"; fail "--plan-only failed"; }
sed 's/^/  /' "$work/planonly.out"
after="$(squeue -h -t all -o %i | wc -l)"
[[ "$before" == "$after" ]] || fail "--plan-only submitted jobs ($before -> $after)"
[[ -x "$work/planonly/.talus/slurm/1/submit.sh" && -f "$work/planonly/.talus/plan.json" ]] \
  || fail "--plan-only wrote no plan or no submit.sh"
[[ ! -e "$work/planonly/.talus/slurm/1/jobs.json" ]] || fail "--plan-only wrote jobs.json"
echo "submit.sh:"
sed 's/^/  /' "$work/planonly/.talus/slurm/1/submit.sh"
m3c2_script="$(ls "$work/planonly/.talus/slurm/1/"*-m3c2.sh)"
echo "$(basename "$m3c2_script"):"
sed 's/^/  /' "$m3c2_script"

echo
echo "slurm campaign test: passed (identical outputs after a Slurm run and after cancel + --resume)"
