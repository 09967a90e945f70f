#!/usr/bin/env python3
"""same_outputs.py A B: exit 0 when directories A and B hold the same outputs, byte for byte.

Every file under A and B but .talus/ is compared, with the one exception the campaign and
resume tests make (tests/campaign/): the timings a run records of itself, the "seconds" values
of summary.json and campaign.json, the seconds column of campaign.csv and the run-time column
of report.html's table (its last cell in each row), are blanked first.
Prints one line per file and a verdict; exit 1 on any difference.
"""
import hashlib
import json
import os
import re
import sys

# The last cell of a row of report.html's table: the pair's run time in seconds.
RUN_TIME = re.compile(r"<td>[0-9][0-9 .,\u202f\u2009]*</td>(\s*)</tr>")


def blank(v):
    if isinstance(v, dict):
        return {k: (None if k == "seconds" else blank(x)) for k, x in v.items()}
    if isinstance(v, list):
        return [blank(x) for x in v]
    return v


def outputs(base):
    out = {}
    for root, dirs, files in os.walk(base):
        rel_root = os.path.relpath(root, base)
        if rel_root == ".talus" or rel_root.startswith(".talus" + os.sep):
            dirs[:] = []
            continue
        dirs[:] = [d for d in dirs if not (rel_root == "." and d == ".talus")]
        for f in files:
            p = os.path.join(root, f)
            name = os.path.normpath(os.path.relpath(p, base))
            data = open(p, "rb").read()
            timed = ""
            if name.endswith("summary.json") or name == "campaign.json":
                data = json.dumps(blank(json.loads(data)), sort_keys=True).encode()
                timed = " (seconds blanked)"
            elif name == "report.html":
                data = RUN_TIME.sub(r"<td>-</td>\1</tr>", data.decode()).encode()
                timed = " (run-time column blanked)"
            elif name == "campaign.csv":
                lines = []
                for line in data.decode().splitlines():
                    c = line.split(",")
                    if len(c) > 14:
                        c[14] = "-"
                    lines.append(",".join(c))
                data = "\n".join(lines).encode()
                timed = " (seconds column blanked)"
            out[name] = (data, timed)
    return out


def main():
    a, b = sys.argv[1], sys.argv[2]
    x, y = outputs(a), outputs(b)
    bad = 0
    for name in sorted(set(x) | set(y)):
        if name not in x or name not in y:
            print(f"  ONLY IN {'B' if name not in x else 'A'}: {name}")
            bad += 1
            continue
        same = x[name][0] == y[name][0]
        bad += not same
        size = len(x[name][0])
        digest = hashlib.sha256(x[name][0]).hexdigest()[:12]
        print(f"  {'same' if same else 'DIFFERENT'}: {name} ({size} bytes, sha256 {digest}){x[name][1]}")
    print(f"same_outputs: {len(x)} files in {a}, {len(y)} in {b}: {'identical' if not bad else f'{bad} differ'}")
    sys.exit(1 if bad else 0)


main()
