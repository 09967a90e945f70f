#!/usr/bin/env python3
"""freeze_claimer.py DIR KIND TIMEOUT [HOST]: wait until a Slurm task of the run in DIR holds a claim on
a unit of stage KIND that is not done yet, SIGSTOP the talus process that holds it, and print
"PID LABEL UNIT" (LABEL is the claim's "slurm <array>_<task>"). With HOST, only a claim taken on
that host (the claim's "host").

nodes.sh uses it to catch a task in the middle of a unit: the St Leonards units take well under
a second, too short to find and kill a node's processes from a shell before the unit is done.
A stopped process computes nothing more and reports nothing (its slurmstepd only learns of
exits), so the node's processes can then be SIGKILLed with the unit still half-way. Claims are
the store's: DIR/.talus/claims/<run>/<kind>/<unit>, JSON with pid, host and label; a unit is
done once DIR/.talus/units/<kind>/<unit>/ exists. Exit 1 when nothing was caught in TIMEOUT s.
"""
import glob
import json
import os
import signal
import sys
import time


def main():
    base, kind, timeout = sys.argv[1], sys.argv[2], float(sys.argv[3])
    host = sys.argv[4] if len(sys.argv) > 4 else None
    work = os.path.join(base, ".talus")
    tried = set()
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        for path in glob.glob(os.path.join(work, "claims", "*", kind, "*")):
            unit = os.path.basename(path)
            try:
                claim = json.load(open(path))
            except (OSError, ValueError):
                continue  # gone, or being written
            pid, label = claim.get("pid"), claim.get("label", "")
            if not label.startswith("slurm ") or (pid, unit) in tried:
                continue
            if host is not None and claim.get("host") != host:
                continue
            tried.add((pid, unit))
            try:
                # The very process that took the claim (not a later one with its pid): the start
                # time the claim records, field 22 of /proc/<pid>/stat, as the store checks it.
                stat = open(f"/proc/{pid}/stat").read()
                if int(stat[stat.rfind(")") + 1 :].split()[19]) != claim.get("pid_start"):
                    continue
                os.kill(pid, signal.SIGSTOP)
            except (OSError, ProcessLookupError):
                continue  # ended in between
            # Stopped. Committed just before the stop (the claim not yet removed)? Then let it go
            # on and catch another one.
            if os.path.isdir(os.path.join(work, "units", kind, unit)):
                os.kill(pid, signal.SIGCONT)
                continue
            print(pid, label.split(" ", 1)[1], unit)
            return 0
        time.sleep(0.005)
    print(f"freeze_claimer: no {kind} unit caught in a Slurm task within {timeout:.0f} s", file=sys.stderr)
    return 1


sys.exit(main())
