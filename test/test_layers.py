"""The layers of the table of docs/architecture.md hold in the code (no ROS): every folder of the packages (and
every module at liver_sim's root) has its row, every import between two of them runs to a lower layer, haptic_bridge
and msg_defs take only liver_sim's base, and the ROS-free cores import no ROS package. Imports are read from the
source (ast), those inside functions included, so a hidden call back up shows too."""
from __future__ import annotations

import ast
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("liver_sim", "haptic_bridge", "msg_defs")
#: liver_sim's root may hold at most this many modules (its __init__ included): the rest sits in folders.
MAX_ROOT_MODULES = 6


def readme_layers() -> dict[str, int]:
    """{folder or root module, as the table writes it without the trailing slash: layer} of the
    table of docs/architecture.md."""
    section = (ROOT / "docs" / "architecture.md").read_text().split("\n## ", 1)[0]
    rows = re.findall(r"^\| (\d+) \| `([\w/.]+?)/?` \|", section, flags=re.M)
    return {path: int(layer) for layer, path in rows}


def place(module: str) -> str:
    """The table's name of the folder (or root module) that holds `module` (dotted)."""
    parts = module.split(".")
    if parts[0] != "liver_sim" or len(parts) == 1:
        return parts[0]
    return f"liver_sim/{parts[1]}" if (ROOT / "liver_sim" / parts[1]).is_dir() else f"liver_sim/{parts[1]}.py"


def modules() -> dict[str, Path]:
    """{dotted name: file} of every module of the packages."""
    found = {}
    for package in PACKAGES:
        for path in (ROOT / package).rglob("*.py"):
            parts = path.relative_to(ROOT).with_suffix("").parts
            found[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    return found


def imports(path: Path) -> set[str]:
    """Every absolute module name `path` imports, at its top or inside a function."""
    names = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names.add(node.module)
        elif isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
    return names


def first_party_edges() -> set[tuple[str, str, str]]:
    """(importing module, its place, the imported place) for every import between two places."""
    edges = set()
    for name, path in modules().items():
        for imported in imports(path):
            if imported.split(".")[0] in PACKAGES and place(imported) != place(name):
                edges.add((name, place(name), place(imported)))
    return edges


def test_every_folder_and_root_module_has_its_row():
    layers = readme_layers()
    places = {place(name) for name in modules()} - {"liver_sim"}
    assert places - set(layers) == set(), "docs/architecture.md: no row for these"
    assert set(layers) - places == set(), "docs/architecture.md: rows for what does not exist"


def test_liver_sims_root_holds_few_modules():
    root_modules = sorted(p.name for p in (ROOT / "liver_sim").glob("*.py"))
    assert len(root_modules) <= MAX_ROOT_MODULES, root_modules


def test_every_import_between_folders_runs_down_a_layer():
    layers = readme_layers()
    upward = sorted(f"{name} ({layers[source]}) imports {target} ({layers[target]})"
                    for name, source, target in first_party_edges() if layers[target] >= layers[source])
    assert not upward


def test_the_layer_check_sees_an_import_back_up(tmp_path, monkeypatch):
    """The control: an import from the base up into the nodes is caught."""
    fake = tmp_path / "liver_sim" / "base" / "upward.py"
    fake.parent.mkdir(parents=True)
    fake.write_text("def f():\n    from liver_sim.nodes.run import spin\n")
    monkeypatch.setattr(sys.modules[__name__], "modules", lambda: {"liver_sim.base.upward": fake})
    layers = readme_layers()
    upward = [(source, target) for _, source, target in first_party_edges() if layers[target] >= layers[source]]
    assert upward == [("liver_sim/base", "liver_sim/nodes")]


@pytest.mark.parametrize("package", ["haptic_bridge", "msg_defs"])
def test_the_cores_beside_the_physics_take_only_the_base_of_liver_sim(package):
    taken = {target for name, _, target in first_party_edges() if name.split(".")[0] == package}
    assert taken <= {"liver_sim/base"}, taken


def test_the_ros_free_cores_import_no_ros_package():
    """Importing the cores and the parameter tables (what offline sessions and the docs test read) loads neither
    rclpy nor a message package."""
    cores = ["haptic_bridge.tick", "haptic_bridge.parameters", "haptic_bridge.supervisor",
    "liver_sim.sessions.analysis",
             "liver_sim.physics.pipeline", "liver_sim.physics.parameters", "liver_sim.tool.parameters",
             "liver_sim.phantom.parameters", "liver_sim.studies.scenarios", "liver_sim.studies.demo_offline",
             "liver_sim.base.topic_names"]
    code = (f"import sys, {', '.join(cores)}; "
            "print(sorted(m for m in sys.modules if m.startswith('rclpy') or m.split('.')[0].endswith('_msgs')))")
    imported = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert imported.strip() == "[]"


def test_each_row_names_every_module_of_its_folder():
    """A newcomer finds each module in its folder's row: its file name in backticks (a subfolder may stand for
    its modules, as `geometry/` does)."""
    section = (ROOT / "docs" / "architecture.md").read_text().split("\n## ", 1)[0]
    rows = dict(re.findall(r"^\| \d+ \| `([\w/.]+?)/?` \|(.*)$", section, flags=re.M))
    unnamed = []
    for folder, text in rows.items():
        if not (ROOT / folder).is_dir():
            continue
        for path in sorted((ROOT / folder).rglob("*.py")):
            relative = path.relative_to(ROOT / folder)
            if path.name != "__init__.py" and f"`{relative.parts[0]}" not in text:
                unnamed.append(f"{folder}/{relative}")
    assert not unnamed, f"docs/architecture.md: modules no row names: {unnamed}"
