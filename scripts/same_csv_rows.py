#!/usr/bin/env python3
"""Checks that two CSVs hold the same rows, whatever their order: each row is
compared as its cells by column name, so the column order may differ too.

    same_csv_rows.py A.csv B.csv [--ignore seconds,seconds_per_epoch]

`--ignore` leaves columns out (wall times differ between runs). Used to check
that a figure run as a grid (`diffdyn figures`: one run per combination, the
parts merged) gives the rows of the same figure run in one program call.
Exit 0 when equal; 1 and the differing rows when not; 2 for a missing file or
different column names.
"""
import argparse
import collections
import csv
import sys


def rows(path, ignore):
    try:
        with open(path, newline="") as f:
            reader = csv.DictReader(f)
            names = [n for n in (reader.fieldnames or []) if n not in ignore]
            return set(names), collections.Counter(tuple((n, r[n]) for n in sorted(names)) for r in reader)
    except OSError as e:
        sys.exit(f"error: {path}: {e.strerror}")


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("a")
    parser.add_argument("b")
    parser.add_argument("--ignore", default="", help="comma-separated columns left out")
    args = parser.parse_args()
    ignore = set(filter(None, args.ignore.split(",")))
    names_a, a = rows(args.a, ignore)
    names_b, b = rows(args.b, ignore)
    if names_a != names_b:
        print(f"error: {args.a} and {args.b} have different columns: {sorted(names_a ^ names_b)}", file=sys.stderr)
        return 2
    if a == b:
        print(f"{args.a} and {args.b}: the same {sum(a.values())} rows")
        return 0
    for row, n in (a - b).items():
        print(f"only in {args.a} ({n}x): {dict(row)}")
    for row, n in (b - a).items():
        print(f"only in {args.b} ({n}x): {dict(row)}")
    return 1


if __name__ == "__main__":
    sys.exit(main())
