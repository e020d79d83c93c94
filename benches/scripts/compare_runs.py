#!/usr/bin/env python3
"""Compares two esgm-bench runs by their ratios, never their absolute figures.

A shared machine moves every absolute figure from hour to hour, so a row is compared
with itself as a ratio of its baseline in the same run (the JSON's `baseline`, or the
one given with --against NAME for rows without one): a row whose p50 ratio grew past
the limit (×1.05 unless --limit says otherwise) since the older run is listed as
slower. Several older files may be given: a row takes its value from the last file that
has it, as the run of record's rows were last committed in several files.

    benches/scripts/compare_runs.py OLD.json [OLD2.json ...] NEW.json [--limit 1.05]

Exits 1 if any row got slower, 0 otherwise, 2 on bad input (a file that is not an
esgm-bench JSON is named).
"""

import argparse
import json
import sys


def load(path):
    """The scenarios of one run, keyed by (name, wait)."""
    try:
        with open(path) as f:
            run = json.load(f)
        rows = run["scenarios"]
    except (OSError, ValueError, KeyError, TypeError) as e:
        sys.exit(f"compare_runs: {path} is not an esgm-bench JSON: {e}")
    return {(r["name"], r["wait"]): r for r in rows if r.get("p50_ns")}


def ratio(rows, key, against):
    """The row's p50 over its baseline's p50 in the same run, with the baseline's name."""
    row = rows.get(key)
    if row is None:
        return None
    base = row.get("baseline") or against
    if not base:
        return None
    base_row = rows.get((base, key[1]))
    if base_row is None or not base_row.get("p50_ns"):
        return None
    return row["p50_ns"] / base_row["p50_ns"], base


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("runs", nargs="+", help="older runs, then the new one")
    parser.add_argument("--limit", type=float, default=1.05)
    parser.add_argument("--against", help="baseline for rows the JSON gives none")
    args = parser.parse_args()
    if len(args.runs) < 2:
        sys.exit("compare_runs: give at least one older run and the new one")
    olds = [load(p) for p in args.runs[:-1]]
    new = load(args.runs[-1])
    slower = 0
    print(f"{'row':44} {'wait':5} {'before':>8} {'now':>8} {'change':>8}  baseline")
    for key in sorted(new):
        now = ratio(new, key, args.against)
        before = None
        for old in olds:
            before = ratio(old, key, args.against) or before
        if now is None or before is None or now[1] != before[1]:
            continue
        change = now[0] / before[0]
        flag = "  SLOWER" if change > args.limit else ""
        slower += bool(flag)
        print(f"{key[0]:44} {key[1]:5} ×{before[0]:<7.3g} ×{now[0]:<7.3g} ×{change:<7.3g}"
              f"  {now[1]}{flag}")
    print(f"{slower} row(s) slower than ×{args.limit} of their last committed ratio")
    return 1 if slower else 0


if __name__ == "__main__":
    sys.exit(main())
