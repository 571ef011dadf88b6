#!/usr/bin/env python3
"""README tables written from the results they cite, and checked against them.

A table in a README is generated from a CSV by a spec in an HTML comment just
above it (invisible when the README is rendered):

    <!-- table from results/summary.csv
    | controller | swung up | cost mean |
    |---|---|---|
    controller=hjb: | HJB policy | **{successes}/{starts}** | {mean_cost:.2f} |
    model=delan,seed=*: | median of seeds | | {sci(median(torque_mse))} |
    -: | a number from elsewhere (named in the row) | 300/300 | 12.6 |
    -->
    ...the table, written by this script...
    <!-- end table -->

Spec lines: the first names the CSV (relative to the README; a .json file, such
as a command's --json output, is one row whose columns are its values flattened:
nominal_rmse_0, parameters_block_inertia_value; several CSVs with
the same columns, separated by spaces, give their rows in turn); lines starting
with `|` are the header (expressions there see every row); every other line is
`FILTER: | cells |`.
FILTER is `-` (a literal row, copied) or `column=value,...` (the CSV rows where
each column equals its value; `*` takes any value). In the cells, `{expr}` or
`{expr:format}` is a Python expression over the matched rows: with one row, a
column name is its value (a number where it parses as one); with several, a
list of the values, for median, mean, min, max, sum, len, zip; at(values, column,
value, ...) is the entry of the one row whose columns equal the values (a grid
cell: at(val_loss, hidden, 32)); pick(values, column, value, ...) the entries of
all such rows. sci(x, digits=3) writes 1.38e-4. wilson(successes, trials) is the
Wilson 95 % interval (low, high) of a success rate, as diffdyn::WilsonInterval.

A number in running text is tied to its results the same way, by a comment
right after it:

    300/300<!-- = {successes}/{starts} from results/summary.csv controller=hjb -->

`= TEMPLATE from CSV [FILTER]`: the text just before the comment must end with
the rendered TEMPLATE (a FILTER of `column=value,...` as above; without one,
the CSV must have one row or the expressions take lists). --write replaces the
number before the comment (letters, digits, . / %, an exponent, and a sign
after a space or an opening mark).

    readme_tables.py --check README.md...   exit 1 and a diff if a table or number differs
    readme_tables.py --write README.md...   rewrite the tables and numbers in place
Bad specs and missing files or columns: `error: FILE:LINE: ...`, exit 2.
"""
import argparse
import csv
import difflib
import functools
import json
import math
import re
import statistics
import sys
from pathlib import Path

BEGIN = re.compile(r"^<!-- table from (\S+(?:\s+\S+)*)\s*$")
END = "<!-- end table -->"
INLINE = re.compile(r"<!-- = (.+?) from (\S+)(?: (\S+))? -->")
# The number before an inline comment: 300/300, 1.38e-4, -0.5, 12 %; a sign only
# after a space or an opening mark, so the range "17-21" ends in the token "21".
TOKEN = re.compile(r"(?:(?<=[\s(*=≈~\[])[-+]|^[-+])?[0-9A-Za-z.%/]+(?:[eE][-+][0-9]+)?$")


class SpecError(Exception):
    pass


def parse_value(text):
    try:
        x = float(text)
    except ValueError:
        return text
    if math.isfinite(x) and x == int(x) and re.fullmatch(r"[+-]?\d+", text.strip()):
        return int(x)
    return x


def sci(x, digits=3):
    """1.38e-4 style: `digits` significant digits, exponent without padding."""
    if x == 0:
        return "0"
    mantissa, exponent = f"{x:.{digits - 1}e}".split("e")
    return f"{mantissa}e{int(exponent)}"


def pick(values, *keys_and_values):
    """The entries of `values` in the rows whose columns equal the given values:
    median(pick(torque_mse, model, "delan"))."""
    if len(keys_and_values) % 2:
        raise ValueError("pick(values, column, value, ...) takes column-value pairs")
    pairs = [(c if isinstance(c, list) else [c], v)
             for c, v in zip(keys_and_values[::2], keys_and_values[1::2])]
    values = values if isinstance(values, list) else [values]
    return [x for i, x in enumerate(values) if all(c[i] == v for c, v in pairs)]


def at(values, *keys_and_values):
    """The one entry of `values` in the row whose columns equal the given values:
    at(val_loss, hidden, 32) or at(mse_j, seed, 1, loss, "f+J")."""
    if len(keys_and_values) % 2:
        raise ValueError("at(values, column, value, ...) takes column-value pairs")
    found = pick(values, *keys_and_values)
    if len(found) != 1:
        raise ValueError(f"{len(found)} rows match {list(keys_and_values[1::2])}")
    return found[0]


def wilson(successes, trials, z=1.96):
    """The Wilson score interval (low, high) of successes / trials (95 % for z = 1.96), the
    formula of diffdyn::WilsonInterval (solvers/statistics.h)."""
    n, p = float(trials), successes / trials
    denom = 1 + z * z / n
    centre = (p + z * z / (2 * n)) / denom
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / denom
    return max(0.0, centre - half), min(1.0, centre + half)


FUNCTIONS = {
    "at": at, "pick": pick, "wilson": wilson,
    "median": statistics.median, "mean": statistics.fmean, "min": min, "max": max,
    "sum": sum, "len": len, "sci": sci, "round": round, "abs": abs, "zip": zip,
}


def flatten(value, prefix, out):
    """A JSON value as columns: objects and lists by key_sub and key_<index>; a list of
    objects that each have a string "name" by key_<name>."""
    if isinstance(value, dict):
        for k, v in value.items():
            flatten(v, f"{prefix}_{k}" if prefix else k, out)
    elif isinstance(value, list):
        named = all(isinstance(v, dict) and isinstance(v.get("name"), str) for v in value) and value
        for i, v in enumerate(value):
            flatten(v, f"{prefix}_{v['name'] if named else i}", out)
    else:
        out[prefix] = value
    return out


@functools.lru_cache(maxsize=None)
def read_csv(path):
    """The rows of a CSV, read once per run however many tables and numbers cite it.
    A .json file (one object, e.g. a command's --json output) is one row of its
    flattened values (flatten)."""
    if str(path).endswith(".json"):
        with open(path) as f:
            return [flatten(json.load(f), "", {})]
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    return [{k: parse_value(v) for k, v in row.items()} for row in rows]


def select(rows, flt, where):
    chosen = rows
    for clause in flt.split(","):
        if "=" not in clause:
            raise SpecError(f"{where}: filter '{flt}' is not column=value,...")
        col, val = (s.strip() for s in clause.split("=", 1))
        if rows and col not in rows[0]:
            raise SpecError(f"{where}: no column '{col}' in the CSV")
        if val != "*":
            chosen = [r for r in chosen if r[col] == parse_value(val)]
    if not chosen:
        raise SpecError(f"{where}: no CSV row matches '{flt}'")
    return chosen


def render_cells(template, chosen, where):
    if len(chosen) == 1:
        names = dict(chosen[0])
    else:
        names = {k: [r[k] for r in chosen] for k in chosen[0]}
    names.update(FUNCTIONS)

    def one(match):
        body = match.group(1)
        expr, fmt = body, ""
        m = re.fullmatch(r"(.*?):([<>^]?[+-]?#?0?\d*(?:\.\d+)?[a-z%]?)", body)
        if m and m.group(2):
            expr, fmt = m.group(1), m.group(2)
        try:
            value = eval(expr, {"__builtins__": {}, **names})  # the README's own spec
            return format(value, fmt)
        except Exception as e:  # noqa: BLE001 - reported with the place
            raise SpecError(f"{where}: cannot evaluate {{{body}}}: {e}") from e

    return re.sub(r"\{([^{}]+)\}", one, template)


def render_table(spec_lines, csv_paths, where_of):
    rows = [row for path in csv_paths for row in read_csv(path)]
    out = []
    for k, line in enumerate(spec_lines):
        where = where_of(k)
        if line.startswith("|"):
            out.append(render_cells(line, rows, where) if rows else line)
            continue
        flt, sep, cells = line.partition(":")
        if not sep or not cells.strip().startswith("|"):
            raise SpecError(f"{where}: expected 'FILTER: | cells |' or a '|' header line")
        flt, cells = flt.strip(), cells.strip()
        out.append(cells if flt == "-" else render_cells(cells, select(rows, flt, where), where))
    return out


def render_inline(line, readme, lineno):
    """`line` with the number before each `<!-- = ... -->` comment regenerated."""
    out, last = [], 0
    for m in INLINE.finditer(line):
        where = f"{readme}:{lineno}"
        template, name, flt = m.group(1), m.group(2), m.group(3)
        path = readme.parent / name
        if not path.is_file():
            raise SpecError(f"{where}: {name}: no such file")
        rows = read_csv(path)
        if not rows:
            raise SpecError(f"{where}: {name} has no rows")
        value = render_cells(template, select(rows, flt, where) if flt else rows, where)
        token = TOKEN.search(line[:m.start()])
        if token is None or token.start() < last:
            raise SpecError(f"{where}: no number before the comment '{m.group(0)}'")
        out.append(line[last:token.start()] + value + m.group(0))
        last = m.end()
    out.append(line[last:])
    return "".join(out)


def process(readme):
    """(old lines, new lines) of the README with every table and inline number
    regenerated."""
    lines = readme.read_text().split("\n")
    new, i = [], 0
    while i < len(lines):
        m = BEGIN.match(lines[i])
        if not m:
            new.append(render_inline(lines[i], readme, i + 1) if "<!-- = " in lines[i] else lines[i])
            i += 1
            continue
        new.append(lines[i])
        start = i
        close = next((j for j in range(i + 1, len(lines)) if lines[j].strip() == "-->"), None)
        if close is None:
            raise SpecError(f"{readme}:{start + 1}: table spec without a closing '-->'")
        end = next((j for j in range(close + 1, len(lines)) if lines[j].strip() == END), None)
        if end is None:
            raise SpecError(f"{readme}:{start + 1}: table without '{END}'")
        csv_paths = [readme.parent / name for name in m.group(1).split()]
        for name, path in zip(m.group(1).split(), csv_paths):
            if not path.is_file():
                raise SpecError(f"{readme}:{start + 1}: {name}: no such file")
        spec = lines[start + 1:close]
        table = render_table(spec, csv_paths, lambda k: f"{readme}:{start + 2 + k}")
        new.extend(lines[start + 1:close + 1])
        new.extend(table)
        new.append(lines[end])
        i = end + 1
    return lines, new


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    mode = parser.add_mutually_exclusive_group(required=True)
    mode.add_argument("--check", action="store_true")
    mode.add_argument("--write", action="store_true")
    parser.add_argument("readmes", nargs="+", type=Path)
    args = parser.parse_args()
    differ = 0
    for readme in args.readmes:
        try:
            if not readme.is_file():
                raise SpecError(f"{readme}: no such file")
            old, new = process(readme)
        except (SpecError, OSError, csv.Error) as e:
            print(f"error: {e}", file=sys.stderr)
            return 2
        if old == new:
            continue
        if args.write:
            readme.write_text("\n".join(new))
            print(f"{readme}: tables and numbers rewritten")
        else:
            differ += 1
            print(f"error: {readme}: a table or number disagrees with the results it cites "
                  f"(scripts/readme_tables.py --write {readme} rewrites it)", file=sys.stderr)
            sys.stderr.writelines(difflib.unified_diff(
                [s + "\n" for s in old], [s + "\n" for s in new], str(readme), "from the results"))
    return 1 if differ else 0


if __name__ == "__main__":
    sys.exit(main())
