#!/usr/bin/env python3
"""Prints the latency rows of an esgm-bench JSON (`--json FILE`) as the Markdown table of
BENCHMARKS.md's "Results" section, so that the table there is the run's own figures,
not figures copied by hand.

Usage: benches/scripts/results_table.py benches/results/results.json
"""
import json
import sys


def duration(ns):
    """A latency as esgm-bench prints it: three significant digits, the unit chosen."""
    if ns < 1_000:
        return f"{ns:.0f} ns"
    for unit, scale in (("µs", 1e3), ("ms", 1e6), ("s", 1e9)):
        value = ns / scale
        if value < 1_000 or unit == "s":
            digits = 2 if value < 10 else 1 if value < 100 else 0
            return f"{value:.{digits}f} {unit}"
    raise AssertionError("unreachable")


def main(path):
    with open(path, encoding="utf-8") as f:
        scenarios = json.load(f)["scenarios"]
    p50 = {(s["name"], s["wait"]): s["p50_ns"] for s in scenarios}
    print("| row | bytes | wait | n | p50 | p99 | p99.9 | max | p50 against its baseline (same wait) |")
    print("|---|---:|---|---:|---:|---:|---:|---:|---|")
    for s in scenarios:
        base = s.get("baseline")
        against = "-"
        if base and p50.get((base, s["wait"])):
            against = f"×{s['p50_ns'] / p50[(base, s['wait'])]:.2f} `{base}`"
        elif base:
            against = f"`{base}` not run"
        cells = [
            f"`{s['name']}`",
            f"{s['payload_bytes']:,}",
            s["wait"],
            f"{s['n']:,}",
            duration(s["p50_ns"]),
            duration(s["p99_ns"]),
            duration(s["p999_ns"]),
            duration(s["max_ns"]),
            against,
        ]
        print("| " + " | ".join(cells) + " |")


if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    main(sys.argv[1])
