#!/usr/bin/env python3
"""docs/stability.md's table from the stability suite's output:
cargo test --test stability -- --nocapture --test-threads 1 | python3 tools/stability_table.py
Reads `STABILITY | case | outcome` lines on stdin; prints a Markdown table grouped by area."""
import re
import sys

rows = []
for line in sys.stdin:
    m = re.search(r"STABILITY \| (.*?) \| (.*)$", line.rstrip("\n"))
    if m:
        rows.append((m.group(1), m.group(2)))
rows.sort(key=lambda r: r[0].split(":")[0])
print("| area | case | outcome |")
print("| --- | --- | --- |")
for case, outcome in rows:
    area, _, name = case.partition(": ")
    # Temporary folders differ per run: keep the file name only.
    outcome = re.sub(r"/tmp/specmux-stab-[^ ]*?/spectra/", "…/spectra/", outcome)
    outcome = re.sub(r"/tmp/specmux-stab-[^/ ]*/", "…/", outcome)
    print(f"| {area} | {name} | {outcome} |")
print(f"\n{len(rows)} cases.")
