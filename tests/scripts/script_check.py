"""Shared by the tests of scripts/: run a script of scripts/ and stop at the first
failed expectation."""
import subprocess
import sys
from pathlib import Path

SCRIPTS = Path(__file__).resolve().parents[2] / "scripts"


def run_script(name, *args):
    """scripts/NAME run with args under this Python: the CompletedProcess (text)."""
    return subprocess.run([sys.executable, str(SCRIPTS / name), *map(str, args)],
                          capture_output=True, text=True)


def expect(cond, what):
    """Prints FAILED: what and exits 1 unless cond."""
    if not cond:
        print(f"FAILED: {what}")
        sys.exit(1)
