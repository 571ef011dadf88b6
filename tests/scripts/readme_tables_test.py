#!/usr/bin/env python3
"""scripts/readme_tables.py on a README it writes itself: a table or an inline
number that agrees passes; a changed result fails with a diff; --write repairs
it; bad specs exit 2."""
import json
import tempfile
from pathlib import Path

from script_check import expect, run_script

README = """# Results

<!-- table from results/scores.csv
| model | seed | error |
|---|---|---|
model=a,seed=0: | A | {seed} | {sci(err)} |
model=a,seed=*: | A, median | {at(seed, err, 0.0003)} | **{sci(median(err))}** |
model=b: | B | {seed} | {err:.2f} |
-: | paper | | 0.5 |
-->
| model | seed | error |
|---|---|---|
| A | 0 | 1.38e-4 |
| A, median | 2 | **2.00e-4** |
| B | 7 | 0.25 |
| paper | | 0.5 |
<!-- end table -->

B's error is **0.25<!-- = {err:.2f} from results/scores.csv model=b -->**, A's median
2.00e-4<!-- = {sci(median(err))} from results/scores.csv model=a,seed=* --> over 3<!-- = {len(seed)} from results/scores.csv model=a,seed=* --> seeds.
"""

CSV = "model,seed,err\na,0,0.000138005\na,1,0.0002\na,2,0.0003\nb,7,0.25\n"


def run(*args):
    return run_script("readme_tables.py", *args)


def expect_agrees(readme, text, what):
    """Writes `text` as the README and expects --check to pass."""
    readme.write_text(text)
    r = run("--check", str(readme))
    expect(r.returncode == 0, f"{what} (rc {r.returncode}: {r.stderr})")


def main():
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        (root / "results").mkdir()
        readme, scores = root / "README.md", root / "results" / "scores.csv"
        readme.write_text(README)
        scores.write_text(CSV)
        r = run("--check", str(readme))
        expect(r.returncode == 0, f"an agreeing table passes (rc {r.returncode}: {r.stderr})")

        scores.write_text(CSV.replace("b,7,0.25", "b,7,0.31"))
        r = run("--check", str(readme))
        expect(r.returncode == 1, "a changed result fails")
        expect("-| B | 7 | 0.25 |" in r.stderr and "+| B | 7 | 0.31 |" in r.stderr, "the diff names the row")
        expect(readme.read_text() == README, "--check leaves the README as it was")

        expect("-B's error is **0.25<!--" in r.stderr and "+B's error is **0.31<!--" in r.stderr,
               "the diff names the inline number")
        r = run("--write", str(readme))
        expect(r.returncode == 0 and "| B | 7 | 0.31 |" in readme.read_text(), "--write repairs the table")
        expect("B's error is **0.31<!-- =" in readme.read_text(), "--write repairs the inline number")
        expect(run("--check", str(readme)).returncode == 0, "the repaired table passes")

        # Two CSVs with the same columns: their rows in turn.
        (root / "results" / "more.csv").write_text("model,seed,err\nc,9,0.5\n")
        two = README.replace("results/scores.csv", "results/scores.csv results/more.csv").replace(
            "-: | paper | | 0.5 |", "model=c: | C | {seed} | {err} |").replace("| paper | | 0.5 |", "| C | 9 | 0.5 |")
        readme.write_text(two)
        scores.write_text(CSV)
        r = run("--check", str(readme))
        expect(r.returncode == 0, f"rows of a second CSV are found (rc {r.returncode}: {r.stderr})")

        # wilson(): the pooled interval of several rows, as diffdyn::WilsonInterval gives it
        # (197 of 200: [95.7, 99.5] %, the 95 % interval of solvers/statistics.h).
        (root / "results" / "trials.csv").write_text("seed,trials,successes\n1,50,50\n4,50,48\n5,100,99\n")
        pooled = ("<!-- table from results/trials.csv\n| seeds | interval |\n|---|---|\n"
                  "seed=*: | all | [{100 * wilson(sum(successes), sum(trials))[0]:.1f}, "
                  "{100 * wilson(sum(successes), sum(trials))[1]:.1f}] % |\n-->\n"
                  "| seeds | interval |\n|---|---|\n| all | [95.7, 99.5] % |\n<!-- end table -->\n")
        expect_agrees(readme, pooled, "wilson() gives the pooled interval")

        # A JSON output is one row of flattened values: lists by index, named objects by name.
        (root / "results" / "run.json").write_text(json.dumps(
            {"model": "m", "rmse": [0.25, 0.5], "parameters": [{"name": "mass", "value": 1.5}]}))
        flat = ("<!-- table from results/run.json\n| rmse y | mass |\n|---|---|\n"
                "model=m: | {rmse_1} | {parameters_mass_value} |\n-->\n"
                "| rmse y | mass |\n|---|---|\n| 0.5 | 1.5 |\n<!-- end table -->\n"
                "x is 0.25<!-- = {rmse_0} from results/run.json -->.\n")
        expect_agrees(readme, flat, "a JSON file gives one flattened row")

        for bad, message in [
            (README.replace("model=b:", "model=c:"), "no CSV row matches"),
            (README.replace("model=b:", "colour=b:"), "no column 'colour'"),
            (README.replace("{err:.2f}", "{erro:.2f}"), "cannot evaluate"),
            (README.replace("<!-- end table -->\n", ""), "without '<!-- end table -->'"),
            (README.replace("results/scores.csv", "results/none.csv"), "no such file"),
            (README.replace("from results/scores.csv model=b -->", "from results/none.csv model=b -->"),
             "results/none.csv: no such file"),
            (README.replace("{len(seed)} from results/scores.csv model=a,seed=*", "{len(seed)} from results/scores.csv model=z"),
             "no CSV row matches 'model=z'"),
            (README.replace("**0.25<!--", "** <!--"), "no number before the comment"),
        ]:
            readme.write_text(bad)
            r = run("--check", str(readme))
            lines = r.stderr.strip().split("\n")
            expect(r.returncode == 2 and len(lines) == 1 and lines[0].startswith("error: ") and
                   message in lines[0], f"bad spec '{message}' -> one error line, exit 2 (got {r.returncode}: {r.stderr})")
            expect(readme.read_text() == bad, "a bad spec leaves the README as it was")
    print("readme_tables: all checks passed")


if __name__ == "__main__":
    main()
