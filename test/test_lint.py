"""What the linter (ruff.toml, `make lint`) cannot check: no Python file over MAX_LINES lines, commit subjects of at
most MAX_SUBJECT characters, with the why in the body, since the linter came, and a test file of its own for every
module of the packages in ONE_FILE_PER_MODULE (docs/development.md, "Tests")."""
from __future__ import annotations

import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
MAX_LINES = 500
MAX_SUBJECT = 72
#: The last commit before the rule: older subjects ran up to 734 characters.
RULE_SINCE = "7f01df8"
#: The packages each of whose modules has a test file of its own: test/<package>/<room>/test_<module>.py.
ONE_FILE_PER_MODULE = ("liver_sim/physics",)


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


def missing_test_files(root: Path, package: str) -> list[str]:
    """The test files test/<package>/<room>/test_<module>.py that the modules of `package` (under `root`) lack."""
    missing = []
    for module in sorted((root / package).rglob("*.py")):
        if module.name != "__init__.py":
            expected = root / "test" / module.parent.relative_to(root) / f"test_{module.name}"
            if not expected.is_file():
                missing.append(str(expected.relative_to(root)))
    return missing


@pytest.mark.parametrize("package", ONE_FILE_PER_MODULE)
def test_every_module_has_its_test_file(package):
    assert missing_test_files(ROOT, package) == []


def test_the_test_file_check_sees_a_module_without_one(tmp_path):
    """The control: a module without its test file is named, and no longer once the file is there."""
    room = tmp_path / "liver_sim" / "physics" / "solver"
    room.mkdir(parents=True)
    (room / "__init__.py").write_text("")
    (room / "newton.py").write_text("")
    assert missing_test_files(tmp_path, "liver_sim/physics") == ["test/liver_sim/physics/solver/test_newton.py"]
    (tmp_path / "test" / "liver_sim" / "physics" / "solver").mkdir(parents=True)
    (tmp_path / "test" / "liver_sim" / "physics" / "solver" / "test_newton.py").write_text("")
    assert missing_test_files(tmp_path, "liver_sim/physics") == []
