"""The documentation agrees with the code (no ROS): docs/contract.md's parameter tables hold every parameter
each node declares and nothing else, with its declared default, range and choices; its topics table every topic
of msg_defs.topics.TOPICS with that topic's type and QoS, its run-time statement the bridge's
RUNTIME_PARAMETERS; every node command line the README and docs/*.md show (`liver_physics --ros-args -p …`,
`ros2 param set …`) sets declared parameters to values its node takes at start, and every `liver-sim …` command
line names options the argument parser has; every file, module and anchor they name exists; the parameter files
set only declared parameters."""
from __future__ import annotations

import argparse
import contextlib
import io
import math
import re
from pathlib import Path

import pytest
import yaml
from doc_text import (
    PLACEHOLDER,
    backticked,
    command_lines,
    items,
    number,
    same_value,
    sections,
    stated_range,
    stated_value,
    tables,
    tokens_of,
    unbracketed,
)

from haptic_bridge.parameters import PARAMETERS as BRIDGE
from haptic_bridge.tick import RUNTIME_PARAMETERS, check_passivity, safe_output
from liver_sim.base.geometry.device_map import DEVICE_MAP_PARAMETERS
from liver_sim.cli.main import build_parser
from liver_sim.phantom.parameters import PARAMETERS as PHANTOM
from liver_sim.phantom.parameters import PhantomParameters
from liver_sim.physics.parameters import PARAMETERS as PHYSICS
from liver_sim.physics.parameters import TOOL_PARAMETERS
from liver_sim.sessions.parameters import node_parameters
from liver_sim.tool.parameters import PARAMETERS as TOOL
from liver_sim.tool.parameters import ToolParameters
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


# -- defaults, ranges and choices of the contract's parameter tables -------------------------------------------

#: Defaults the contract describes in words rather than states, and what it says instead.
DESCRIBED_DEFAULTS = {"support_regions": "listed in config/liver_physics.yaml",
                      "static_position_m": "10 mm above the default liver's dome",
                      "nodes_topic": "the topics table", "surface_topic": "the topics table",
                      "marker_topic": "the topics table"}
#: Choices the contract describes by a link rather than lists.
DESCRIBED_CHOICES = {"force_output": "the encodings table"}
def parameter_rows(node: str):
    """(names, default cell, range cell) of each row of `node`'s parameter tables that names parameters."""
    for cells in tables(sections(CONTRACT.read_text())[node], "parameter"):
        names = [name for name in backticked(cells[0]) if PARAMETER_NAME.fullmatch(name)]
        if names:
            yield names, cells[1], cells[2]


@pytest.mark.parametrize("node", NODES)
def test_documented_defaults_are_the_declared_ones(node):
    wrong = []
    for names, cell, _ in parameter_rows(node):
        stated = items(cell)
        values = [stated_value(item) for item in stated] if len(stated) == len(names) else [None] * len(names)
        for name, value in zip(names, values):
            if value is None:
                if name not in DESCRIBED_DEFAULTS:
                    wrong.append(f"{name}: default {cell!r} states no value")
            elif not same_value(value, NODES[node][name].default):
                wrong.append(f"{name}: {cell!r}, declared {NODES[node][name].default!r}")
    assert not wrong, f"docs/contract.md, section {node}: {wrong}"


@pytest.mark.parametrize("node", NODES)
def test_documented_ranges_and_choices_are_the_declared_ones(node):
    wrong, previous = [], []
    for names, _, cell in parameter_rows(node):
        stated = previous if cell == "as above" else items(cell)
        previous = stated
        choices = [c for c in backticked(cell)] if cell.startswith("`") else None
        for i, name in enumerate(names):
            spec = NODES[node][name]
            if choices is not None:
                ok = len(names) == 1 and set(choices) == set(spec.choices or ())
            elif cell in DESCRIBED_CHOICES.get(name, ()) or name in DESCRIBED_CHOICES:
                ok = spec.choices is not None
            else:
                # an item may name what it bounds (`radius 0.01–10`); otherwise the items go by position
                labelled = {item.split()[0]: item.split(None, 1)[1] for item in stated if item[0].isalpha()}
                item = next((text for word, text in labelled.items() if word in name), None)
                if item is None and not labelled:
                    item = stated[0] if len(stated) == 1 else stated[i] if i < len(stated) else None
                declared = None if spec.low is None else (float(spec.low), float(spec.high))
                ok = (stated_range(item) if item else None) == declared or (
                    declared is not None and item is not None and stated_range(item) is not None
                    and all(math.isclose(a, b, rel_tol=1e-3) for a, b in zip(stated_range(item), declared)))
                ok = ok and spec.choices is None
            if not ok:
                wrong.append(f"{name}: {cell!r}, declared {spec.low}–{spec.high} {spec.choices or ''}")
    assert not wrong, f"docs/contract.md, section {node}: {wrong}"


def test_documented_script_defaults_are_the_declared_ones():
    scripts = sections(sections(CONTRACT.read_text())["phantom_sim"], "### ")["Scripts"]
    defaults = scripts[scripts.index("Defaults:"):]
    stated = dict(re.findall(r"`(\w+)` ([−\d.]+)", defaults))
    assert set(stated) >= {"depth_m", "clearance_m", "slide_m", "pull_m", "approach_s", "hand_speed_m_s"}
    wrong = {name: value for name, value in stated.items()
             if not same_value(number(value), SCRIPT_PARAMETERS[name].default)}
    assert not wrong, f"docs/contract.md, Scripts: {wrong}"


#: A value the prose gives a parameter, `name` (150 Hz), `name`, default 5 ms: a number with its unit, and the
#: factor from that unit to the parameter's SI unit.
PROSE_DEFAULT = re.compile(r"`([a-z][a-z0-9_]*)`,? \(?(?:default )?([−-]?[\d.]+(?:·10[⁰¹²³⁴⁵⁶⁷⁸⁹]+)?) "
                           r"?(ms|mm|cm|s|m|Hz|N/m|N·s/m|N|m/s|kPa|Pa·s)(?=[ ,;)])")
UNIT_FACTORS = {"ms": 1e-3, "mm": 1e-3, "cm": 1e-2}


@pytest.mark.parametrize("doc", DOCS, ids=lambda d: d.name)
def test_defaults_stated_in_prose_are_the_declared_ones(doc):
    """`lifetime_s` (50 ms) in a sentence is the default of a node that declares `lifetime_s`."""
    declared = {}
    for table in NODES.values():
        for name, spec in table.items():
            declared.setdefault(name, []).append(spec.default)
    wrong = []
    for name, value, unit in PROSE_DEFAULT.findall(doc.read_text()):
        stated = number(value) * UNIT_FACTORS.get(unit, 1.0)
        if name in declared and not any(same_value(stated, default) for default in declared[name]):
            wrong.append(f"`{name}` {value} {unit}, declared {declared[name]}")
    assert not wrong, f"{doc.relative_to(ROOT)}: {wrong}"


# -- command lines -------------------------------------------------------------------------------------------

EXECUTABLES = (*NODES, "liver-sim")


def node_command_problem(node: str, tokens: list[str]) -> str | None:
    """Why the node command line `tokens` (after the executable) would not start the node as written, or None:
    ROS arguments before `--ros-args`, a first parameter file not the node's, an override of an undeclared parameter,
    a value the node refuses at start (type, range, the bridge's passivity and rate limit)."""
    if "--ros-args" in tokens:
        before, ros = tokens[:tokens.index("--ros-args")], tokens[tokens.index("--ros-args") + 1:]
    else:
        before, ros = tokens, []
    stray = [t for t in before if t not in ("--managed", "…") or (t == "--managed" and node != "haptic_bridge")]
    if stray:
        return f"{stray} before --ros-args"
    overrides = []
    params_files = [value for flag, value in zip(ros, ros[1:]) if flag == "--params-file"]
    if params_files and not params_files[0].endswith(f"config/{node}.yaml") and not PLACEHOLDER.fullmatch(
            params_files[0]):  # a further file (a segmented liver's support) may follow the node's own
        return f"--params-file {params_files[0]} is not the node's config/{node}.yaml"
    for flag, value in zip(ros, ros[1:]):
        if flag == "-p":
            overrides.append(value)
    try:
        if node in ("liver_physics", "haptic_bridge"):
            p = node_parameters([f"{node}.{o}" for o in overrides])[node]
            if node == "haptic_bridge":
                if p.drives_device:
                    check_passivity(p)
                safe_output(p)
        else:
            record = {"liver_tool": ToolParameters, "phantom_sim": PhantomParameters}[node]
            values = {name: spec.default for name, spec in NODES[node].items()}
            values.update(yaml.safe_load((ROOT / "config" / f"{node}.yaml").read_text())[node]["ros__parameters"])
            for override in overrides:
                name, _, raw = override.partition(":=")
                if name not in NODES[node]:
                    return f"{name} is not a parameter of {node}"
                values[name] = yaml.safe_load(raw)
            record.from_values(values)
    except ValueError as exc:
        return str(exc)
    return None


def param_set_problem(tokens: list[str]) -> str | None:
    """Why `ros2 param set NODE NAME VALUE` names an unknown node or parameter, or a value out of range."""
    if len(tokens) < 5 or PLACEHOLDER.fullmatch(tokens[3]):
        return None
    node, name, value = tokens[3].rsplit("/", 1)[-1], tokens[4], " ".join(tokens[5:])
    if node not in NODES:
        return f"no node {node}"
    short = name.split(".", 1)[-1] if node == "liver_physics" and name.split(".", 1)[-1] in TOOL_PARAMETERS else name
    if short not in NODES[node]:
        return f"{name} is not a parameter of {node}"
    return node_command_problem(node, ["--ros-args", "-p", f"{short}:={value}"]) if value else None


def subcommand(parser: argparse.ArgumentParser, tokens: list[str]) -> tuple[argparse.ArgumentParser, list[str]]:
    """The deepest subcommand parser `tokens` name, and the tokens after its name."""
    while tokens:
        commands = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
        if not commands or tokens[0] not in commands[0].choices:
            break
        parser, tokens = commands[0].choices[tokens[0]], tokens[1:]
    return parser, tokens


def cli_command_problem(tokens: list[str], block: bool) -> str | None:
    """Why the `liver-sim` command line `tokens` (after `liver-sim`; a synopsis with `[…]` and `a|b` is read
    option by option) names an unknown command or option, an option value outside its choices, or a `-p`
    override the physics and the bridge refuse; a complete command from a code block is parsed whole."""
    root = build_parser()
    words = [word for word in map(unbracketed, tokens) if word]
    if words[:1] == ["--discovery-range"]:
        words = words[2:]
    if not words or PLACEHOLDER.fullmatch(words[0]) or words[0] in ("-h", "--help"):
        return None
    parser, rest = subcommand(root, words)
    if parser is root:
        return f"no command {words[0]!r}"
    options = {option: action for action in parser._actions for option in action.option_strings}
    overrides = []
    for option, value in zip(rest, [*rest[1:], ""]):
        if not option.startswith("-") or re.fullmatch(r"-?[\d.]+", option):
            continue
        action = options.get(option.split("=", 1)[0])
        if action is None:
            return f"{parser.prog}: no option {option}"
        if option == "-p" and value and not PLACEHOLDER.fullmatch(value.split(":=")[0]) and "name:=" not in value:
            overrides.append(value)
        if action.choices and value and not PLACEHOLDER.fullmatch(value) and not value.startswith("-"):
            outside = [v for v in value.split("|") if v not in map(str, action.choices)]
            if outside:
                return f"{parser.prog} {option}: {outside} not in {list(action.choices)}"
    try:
        node_parameters(overrides)
    except ValueError as exc:
        return str(exc)
    complete = not any(c in " ".join(tokens) for c in "[|…") and not any(PLACEHOLDER.fullmatch(t) for t in tokens)
    if block and complete:
        with contextlib.redirect_stderr(io.StringIO()) as stderr:
            try:
                root.parse_args(tokens)
            except SystemExit:
                return stderr.getvalue().strip().splitlines()[-1]
    return None


def documented_commands() -> list[tuple[str, str, bool]]:
    return [(doc.relative_to(ROOT).as_posix(), command, block)
            for doc in DOCS for command, block in command_lines(doc.read_text(), EXECUTABLES)]


@pytest.mark.parametrize("doc, command, block", documented_commands(), ids=lambda v: v if isinstance(v, str) else "")
def test_documented_command_lines_run_as_written(doc, command, block):
    tokens = tokens_of(command)
    if tokens[0] == "liver-sim":
        problem = cli_command_problem(tokens[1:], block)
    elif tokens[:3] == ["ros2", "param", "set"]:
        problem = param_set_problem(tokens)
    else:
        problem = node_command_problem(tokens[0], tokens[1:])
    assert problem is None, f"{doc}: `{command}`: {problem}"


@pytest.mark.parametrize("command, problem", [
    ("liver_physics -p tearing:=true", "before --ros-args"),
    ("liver_physics --ros-args -p tearing:=3", "tearing"),
    ("liver_physics --ros-args -p no_such_parameter:=1", "no_such_parameter"),
    ("haptic_bridge --ros-args --params-file config/haptic_bridge.yaml -p local_model:=none", "not passive"),
    ("liver_tool --ros-args --params-file config/haptic_bridge.yaml", "config/liver_tool.yaml"),
    ("phantom_sim --ros-args -p max_force_n:=5.0", "max_force_n"),
    ("liver-sim demo --no-such-option", "no option"),
    ("liver-sim demo --scenario press|squeeze", "squeeze"),
    ("liver-sim resimulate BAG -p no_such_parameter:=1", "no_such_parameter"),
    ("liver-sim frobnicate", "no command"),
])
def test_a_wrong_command_line_is_caught(command, problem):
    tokens = tokens_of(command)
    found = (cli_command_problem(tokens[1:], True) if tokens[0] == "liver-sim"
             else node_command_problem(tokens[0], tokens[1:]))
    assert found is not None and problem in found, found


def test_a_wrong_default_is_caught():
    assert [(n, v, u) for n, v, u in PROSE_DEFAULT.findall("the bridge's `lifetime_s` (40 ms) and")] == [
        ("lifetime_s", "40", "ms")]
    assert not same_value(stated_value("0.45"), 0.4)
    assert not same_value(stated_value("`sphere`"), "plane")
    assert same_value(stated_value("3·10⁷"), 3e7) and same_value(stated_value("[0, 0, 0]"), [0.0, 0.0, 0.0])
    assert stated_range("0.01–10⁴") == (0.01, 1e4) and stated_range("50–2 000 000") == (50.0, 2e6)
