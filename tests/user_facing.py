"""What the command-line tests share: running a command as a user would, in process or as the installed console
script, and the rules of readable output."""

import re
import shutil
import sys
from pathlib import Path

from workflow.cli import main

REPR = re.compile(r"\w+\(\w+=|[\[\]{}]")
"""Python reprs in human output: ``Law(q0=...)``, lists, dicts."""
NUMBER = re.compile(r"\d+(?:\.\d+)?")
MAX_DIGITS = 8
"""Most significant digits a number in human output may show."""
HIDDEN_REFERENCE = re.compile(r"\b" + "spec".upper() + r"\b")
"""The name of the specification file users never see, as a whole word in capitals."""
SAMPLE_CAMPAIGN = Path(__file__).resolve().parents[1] / "data" / "sample_campaign.csv"
"""The sample campaign shipped in the repository's data/ folder."""
TACTILE = [shutil.which("tactile", path=str(Path(sys.executable).parent)) or "tactile"]
"""The installed console script of the environment running the tests (never the checkout: ``python -m`` or
``python -c`` would import the package from the working directory first)."""


def run_cli(capsys, *argv):
    """(exit status, stdout, stderr) of ``tactile ARGV`` run in this process."""
    try:
        status = main([str(a) for a in argv])
    except SystemExit as exit_:
        status = exit_.code
    out, err = capsys.readouterr()
    return status, out, err


def assert_readable(text: str) -> None:
    """No Python repr, no long float, micrometres as µm (file paths, which may hold anything, are skipped)."""
    words = " ".join(word for word in text.split() if "/" not in word or word in ("m/s", "pm/V", "s^2/m^2", "s/m"))
    assert not REPR.search(words), text
    assert all(len(n.replace(".", "").lstrip("0")) <= MAX_DIGITS for n in NUMBER.findall(words)), text
    assert not re.search(r"\bum\b", words), text
