#!/usr/bin/env python3
"""Checks the page `diffdyn figures` writes (DIR/index.html).

    check_figures_page.py DIR/index.html [--manifest paper_figures/figures.json]

Exit 0 when
  * every <img src> and <a href> that is not an anchor or a URL names an existing file
    relative to the page;
  * every number cell (class "ours", or "pytorch" for a benchmark's PyTorch time) equals what its recipe gives when recomputed here
    from the CSV with Python's csv module (data-csv, data-where "col=val;...",
    data-column, data-reduce: value | median | mean | min | max | count), printed to
    4 significant digits, and a cell that says "missing" has no value here either;
  * with --manifest: every figure has a section with every listed PNG shown and one
    number cell per listed number;
  * with --no-missing: no number cell says "missing" (a stored run must give them all).
Otherwise it prints one line per failure and exits 1.
"""
import argparse
import csv
import html.parser
import json
import math
import os
import statistics
import sys


class Page(html.parser.HTMLParser):
    def __init__(self):
        super().__init__()
        self.links = []      # (tag, target)
        self.cells = []      # (attrs, text)
        self.sections = {}   # id -> {"images": [...], "cells": n}
        self._section = None
        self._cell = None

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        if tag == "section":
            self._section = a.get("id")
            self.sections[self._section] = {"images": [], "cells": 0}
        if tag == "img":
            self.links.append(("img", a.get("src", "")))
            if self._section:
                self.sections[self._section]["images"].append(os.path.basename(a.get("src", "")))
        if tag == "a" and "href" in a:
            self.links.append(("a", a["href"]))
        if tag == "td" and a.get("class") in ("ours", "pytorch"):
            self._cell = [a, ""]

    def handle_data(self, data):
        if self._cell is not None:
            self._cell[1] += data

    def handle_endtag(self, tag):
        if tag == "td" and self._cell is not None:
            self.cells.append((self._cell[0], self._cell[1].strip()))
            if self._section and self._cell[0].get("class") == "ours":
                self.sections[self._section]["cells"] += 1
            self._cell = None
        if tag == "section":
            self._section = None


def recompute(root, attrs):
    """The number of one cell's recipe, or None when it has none."""
    path = os.path.join(root, attrs["data-csv"])
    if not os.path.isfile(path):
        return None
    where = [w.split("=", 1) for w in attrs["data-where"].split(";") if w]
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    if rows and (attrs["data-column"] not in rows[0] or any(c not in rows[0] for c, _ in where)):
        return None
    cells = [r[attrs["data-column"]] for r in rows if all(r[c] == v for c, v in where)]
    how = attrs["data-reduce"]
    if not cells or (how == "value" and len(cells) != 1):
        return None
    try:
        values = [float(c) for c in cells]
    except ValueError:
        return None
    if not all(math.isfinite(v) for v in values):
        return None
    return {"value": values[0], "median": statistics.median(values), "mean": statistics.fmean(values),
            "min": min(values), "max": max(values), "count": float(len(values))}[how]


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("page")
    parser.add_argument("--manifest")
    parser.add_argument("--no-missing", action="store_true")
    args = parser.parse_args()
    root = os.path.dirname(os.path.abspath(args.page))
    page = Page()
    with open(args.page, encoding="utf-8") as f:
        page.feed(f.read())
    failures = []
    for tag, target in page.links:
        if target.startswith("#") or "://" in target:
            continue
        if not os.path.isfile(os.path.join(root, target)):
            failures.append(f"<{tag}> {target}: no such file")
    for attrs, text in page.cells:
        expected = recompute(root, attrs)
        name = f"{attrs['data-csv']} [{attrs['data-where']}] {attrs['data-reduce']} of {attrs['data-column']}"
        if expected is None and args.no_missing:
            failures.append(f"{name}: missing ({text})")
        elif expected is None:
            if not text.startswith("missing"):
                failures.append(f"{name}: the page shows {text}, the CSV gives no value")
        elif text != f"{expected:.4g}":
            failures.append(f"{name}: the page shows {text}, the CSV gives {expected:.4g}")
    if args.manifest:
        with open(args.manifest) as f:
            manifest = json.load(f)
        for fig in manifest["figures"]:
            section = page.sections.get(fig["name"])
            if section is None:
                failures.append(f"{fig['name']}: no section on the page")
                continue
            for image in fig["images"]:
                if image not in section["images"]:
                    failures.append(f"{fig['name']}: {image} not shown")
            if section["cells"] != len(fig["numbers"]):
                failures.append(f"{fig['name']}: {section['cells']} number cells, manifest lists {len(fig['numbers'])}")
    for line in failures:
        print(line)
    print(f"{len(page.links)} links, {len(page.cells)} numbers checked; {len(failures)} failures")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
