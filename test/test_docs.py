"""The documentation agrees with the code (no ROS): docs/contract.md's parameter tables hold every parameter
each node declares and nothing else, its topics table every topic of msg_defs.topics.TOPICS with that
topic's type and QoS, its run-time statement the bridge's RUNTIME_PARAMETERS; and every file, module and
anchor the README and docs/*.md name exists; the parameter files set only declared parameters."""
from __future__ import annotations

import re
from pathlib import Path

import pytest
import yaml

from haptic_bridge.parameters import PARAMETERS as BRIDGE
from haptic_bridge.tick import RUNTIME_PARAMETERS
from liver_sim.base.geometry.device_map import DEVICE_MAP_PARAMETERS
from liver_sim.phantom.parameters import PARAMETERS as PHANTOM
from liver_sim.physics.parameters import PARAMETERS as PHYSICS
from liver_sim.tool.parameters import PARAMETERS as TOOL
from liver_sim.tool.scripts import SCRIPT_PARAMETERS
from msg_defs.topics import TOPICS

ROOT = Path(__file__).resolve().parent.parent
CONTRACT = ROOT / "docs" / "contract.md"
DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
#: Each node's section of the contract (its `## title`) and its declared parameters.
NODES = {"liver_physics": PHYSICS, "haptic_bridge": BRIDGE, "liver_tool": TOOL, "phantom_sim": PHANTOM}
PARAMETER_NAME = re.compile(r"[a-z][a-z0-9]*(?:_[a-z0-9]+)*")
#: Repository paths as the docs write them: from a top-level folder of the repository.
PATH = re.compile(r"(?<![\w/.$<{-])((?:liver_sim|haptic_bridge|msg_defs|docs|config|test|resource|\.ci)/[\w./<>-]*)")
#: Dotted module references (`msg_defs.topics.device_command_qos`), not `haptic_bridge.rate_hz:=…` overrides.
MODULE_REFERENCE = re.compile(r"(?<![\w/.])((?:liver_sim|haptic_bridge|msg_defs)(?:\.[A-Za-z_]\w*)+)(?![\w.]*:=)")
LINK = re.compile(r"\]\(([^)\s]+)\)")


def sections(text: str, level: str = "## ") -> dict[str, str]:
    """{title: body} of the `level` headings of a markdown text (a body keeps its deeper subsections)."""
    parts = re.split(rf"^{level}(.+)$", text, flags=re.M)
    return {title.strip(): body for title, body in zip(parts[1::2], parts[2::2])}


def tables(body: str, first_header: str) -> list[list[str]]:
    """The rows (cells, stripped; `\\|` is a pipe within a cell) of every table in `body` whose first column
    header is `first_header`."""
    rows, current = [], None
    for line in body.splitlines():
        if not line.startswith("|"):
            current = None
            continue
        cells = [c.strip() for c in re.split(r"(?<!\\)\|", line.strip())[1:-1]]
        if current is None:
            current = cells[0] == first_header
        elif current and not set(cells[0]) <= set("-: "):
            rows.append(cells)
    return rows


def backticked(text: str) -> list[str]:
    return re.findall(r"`([^`]+)`", text)


def documented_parameters(node: str) -> set[str]:
    """The parameter names in the first column of `node`'s parameter tables in the contract (a
    `script parameters` row stands for the names of the Scripts subsection)."""
    contract = sections(CONTRACT.read_text())
    names = set()
    for cells in tables(contract[node], "parameter"):
        if cells[0] == "script parameters":
            names |= set(backticked(sections(contract["phantom_sim"], "### ")["Scripts"])) & set(SCRIPT_PARAMETERS)
        names |= {name for name in backticked(cells[0]) if PARAMETER_NAME.fullmatch(name)}
    return names


@pytest.mark.parametrize("node", NODES)
def test_every_declared_parameter_is_in_its_nodes_table(node):
    missing = sorted(set(NODES[node]) - documented_parameters(node))
    assert not missing, f"docs/contract.md, section {node}: no table row for {missing}"


@pytest.mark.parametrize("node", NODES)
def test_parameter_tables_name_only_declared_parameters(node):
    unknown = sorted(documented_parameters(node) - set(NODES[node]))
    assert not unknown, f"docs/contract.md, section {node}: {unknown} are not parameters of {node}"


def test_the_device_map_is_declared_by_the_tool_and_the_phantom_only():
    for node in ("liver_tool", "phantom_sim"):
        assert set(DEVICE_MAP_PARAMETERS) <= documented_parameters(node)
    assert not set(DEVICE_MAP_PARAMETERS) & documented_parameters("haptic_bridge")


@pytest.mark.parametrize("doc, paragraph", [(CONTRACT, "- Every node answers every run-time change"),
                                            (ROOT / "docs" / "haptic-safety.md", "## Run-time parameters")])
def test_the_bridges_run_time_parameters_are_those_it_takes(doc, paragraph):
    text = doc.read_text()
    text = text[text.index(paragraph):]
    bridge_part = text[text.index("`haptic_bridge`"):text.index("`liver_tool`")]
    assert set(backticked(bridge_part)) & set(BRIDGE) == RUNTIME_PARAMETERS, doc.name


@pytest.mark.parametrize("key", TOPICS)
def test_every_topic_has_its_row_with_type_and_qos(key):
    topic = TOPICS[key]
    rows = {cells[0]: cells for cells in tables(sections(CONTRACT.read_text())["Topics"], "topic")}
    cells = rows.get(f"`{topic.name}`")
    assert cells is not None, f"docs/contract.md, Topics: no row for {topic.name}"
    if topic.type is not None:
        assert f"`{topic.type.__module__.split('.')[0]}/{topic.type.__name__}`" in cells[1], topic.name
    qos = (f"{'reliable' if topic.reliable else 'best effort'}, "
           f"{'transient local' if topic.transient_local else 'volatile'}, depth {topic.depth}")
    assert re.match(rf"{re.escape(qos)}\b", cells[-1]), f"{topic.name}: {cells[-1]!r}, not {qos!r}"
    assert f"`{topic.name}`" in (ROOT / "README.md").read_text(), f"README: no {topic.name}"


def _module_file(parts: list[str]) -> tuple[Path, list[str]]:
    """The source file of the longest module prefix of the dotted `parts` (found on disk: nothing is imported)
    and the names after it."""
    for i in range(len(parts), 0, -1):
        base = ROOT.joinpath(*parts[:i])
        for source in (base.with_suffix(".py"), base / "__init__.py"):
            if source.is_file():
                return source, parts[i:]
    raise AssertionError(f"no module {'.'.join(parts)}")


def _anchors(doc: Path) -> set[str]:
    """GitHub's anchors of the headings of `doc`."""
    titles = re.findall(r"^#+ (.+)$", doc.read_text(), flags=re.M)
    return {re.sub(r"[^\w\- ]", "", title.strip().lower()).replace(" ", "-") for title in titles}


@pytest.mark.parametrize("doc", DOCS, ids=lambda d: d.name)
def test_named_files_modules_and_links_exist(doc):
    text = doc.read_text()
    missing = []
    for path in PATH.findall(text):
        path = path.rstrip(".,")
        if "<" not in path and not (ROOT / path).exists():
            missing.append(path)
    for link in LINK.findall(text):
        if re.match(r"[a-z]+:", link):
            continue
        target, _, anchor = link.partition("#")
        target_path = (doc.parent / target).resolve() if target else doc
        if not target_path.exists():
            missing.append(link)
        elif anchor and target_path.suffix == ".md" and anchor not in _anchors(target_path):
            missing.append(link)
    for reference in MODULE_REFERENCE.findall(text):
        module, rest = _module_file(reference.split("."))
        if len(rest) > 1 or (rest and not re.search(rf"^(?:def|class) {rest[0]}\b|^{rest[0]}\s*[:=]",
                                                    module.read_text(), flags=re.M)):
            missing.append(reference)
    assert not missing, f"{doc.relative_to(ROOT)} names what does not exist: {missing}"


@pytest.mark.parametrize("node", NODES)
def test_config_files_set_only_declared_parameters(node):
    """config/<node>.yaml, which the contract names as each node's parameter file, sets only its parameters."""
    values = yaml.safe_load((ROOT / "config" / f"{node}.yaml").read_text())[node]["ros__parameters"]
    unknown = sorted(set(values) - set(NODES[node]))
    assert not unknown, f"config/{node}.yaml: {unknown} are not parameters of {node}"
