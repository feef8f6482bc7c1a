"""What the linter (ruff.toml, `make lint`) cannot check: no Python file over MAX_LINES lines, and commit
subjects of at most MAX_SUBJECT characters, with the why in the body, since the linter came."""
from __future__ import annotations

import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
MAX_LINES = 500
MAX_SUBJECT = 72
#: The last commit before the rule: older subjects ran up to 734 characters.
RULE_SINCE = "7f01df8"


def tracked_python_files() -> list[Path]:
    try:
        listed = subprocess.run(["git", "ls-files", "*.py"], cwd=ROOT, capture_output=True, text=True, check=True)
    except (OSError, subprocess.CalledProcessError):
        return sorted(ROOT.glob("[!.]*/**/*.py")) + sorted(ROOT.glob("*.py"))
    return [ROOT / name for name in listed.stdout.split()]


def test_no_python_file_is_over_the_limit():
    files = tracked_python_files()
    assert files
    long = {str(f.relative_to(ROOT)): n for f in files if (n := len(f.read_text().splitlines())) > MAX_LINES}
    assert not long, f"over {MAX_LINES} lines: {long}"


def test_commit_subjects_are_short():
    try:
        log = subprocess.run(["git", "log", "--format=%h %s", f"{RULE_SINCE}..HEAD"], cwd=ROOT,
                             capture_output=True, text=True, check=True).stdout
    except (OSError, subprocess.CalledProcessError):
        pytest.skip(f"no git history with {RULE_SINCE} here (not a clone, or a shallow one)")
    long = [line for line in log.splitlines() if len(line.split(" ", 1)[1]) > MAX_SUBJECT]
    assert not long, f"commit subjects over {MAX_SUBJECT} characters: {long}"
