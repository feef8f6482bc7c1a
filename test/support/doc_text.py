"""Facts read out of the project's markdown (no ROS, no project import): sections, table rows, backticked names,
the values, ranges and command lines the docs write, for test/test_docs.py to hold against the code."""
from __future__ import annotations

import math
import re
import shlex


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
    """The `code spans` of `text`."""
    return re.findall(r"`([^`]+)`", text)


#: Superscript digits as the docs write powers of ten (10⁶), and a number the docs write.
SUPERSCRIPTS = str.maketrans("⁰¹²³⁴⁵⁶⁷⁸⁹⁻", "0123456789-")
NUMBER = re.compile(r"(?P<mantissa>[−-]?\d+(?: \d{3})*(?:\.\d+)?)?"
                    r"(?:(?(mantissa)·)10(?P<exponent>[⁰¹²³⁴⁵⁶⁷⁸⁹⁻]+))?")
#: The identity quaternion (x, y, z, w), what the docs call "identity".
IDENTITY_XYZW = [0.0, 0.0, 0.0, 1.0]


def number(text: str) -> float | None:
    """The number `text` writes (`1 150`, `−0.0462`, `3·10⁷`, `10⁶`), or None."""
    match = NUMBER.fullmatch(text.strip())
    if not match or not text.strip():
        return None
    mantissa = float(match["mantissa"].replace(" ", "").replace("−", "-")) if match["mantissa"] else 1.0
    exponent = int(match["exponent"].translate(SUPERSCRIPTS)) if match["exponent"] else 0
    return mantissa * 10.0 ** exponent


def items(cell: str) -> list[str]:
    """The comma-separated items of a table cell, commas inside brackets, parentheses or backticks kept."""
    parts, depth, quoted, current = [], 0, False, ""
    for char in cell:
        quoted ^= char == "`"
        depth += (char in "[(") - (char in "])")
        if char == "," and depth == 0 and not quoted:
            parts.append(current.strip())
            current = ""
        else:
            current += char
    return [part for part in [*parts, current.strip()] if part]


def stated_value(text: str):
    """The value a default item states (`plane`, `""`, 0.05, [0, 0, 0], true, `[""]`, identity), or None when it
    describes the default in words."""
    text = re.sub(r"\s*\([^)]*\)$", "", text.strip())
    if re.fullmatch(r"`[^`]*`", text):
        text = text[1:-1]
        if not text.startswith("["):
            return "" if text == '""' else text
    if text in ("true", "false"):
        return text == "true"
    if text == "identity":
        return IDENTITY_XYZW
    if text.startswith("[") and text.endswith("]"):
        values = [stated_value(item) for item in items(text[1:-1])]
        return None if None in values else values
    if text == '""':
        return ""
    return number(text)


def same_value(stated, declared) -> bool:
    if isinstance(declared, bool) or isinstance(stated, bool):
        return stated is declared
    if isinstance(declared, (int, float)):
        return isinstance(stated, float) and math.isclose(stated, declared, rel_tol=1e-3, abs_tol=1e-12)
    if isinstance(declared, (list, tuple)):
        return (isinstance(stated, list) and len(stated) == len(declared)
                and all(same_value(s, d) for s, d in zip(stated, declared)))
    return stated == declared


def stated_range(text: str):
    """(low, high) of a range item (`0.01–10⁴`, `0–1 s`), a tuple of choices (`` `a`, `b` ``), or None."""
    match = re.fullmatch(r"(.+?)–(.+?)(?: [a-zA-Z/]+)?", text.strip())
    if match and number(match[1]) is not None and number(match[2]) is not None:
        return number(match[1]), number(match[2])
    return None


#: A placeholder the docs write for a value (BAG, DIR, S, TETS, …).
PLACEHOLDER = re.compile(r"[A-Z][A-Z0-9_]*|…|\.\.\.")


def command_lines(text: str, executables) -> list[tuple[str, bool]]:
    """(command, from a code block) for every command line the text shows: each line of a code block (a line
    ending in `\\` joined with the next; `# comments` dropped) and each inline code span, that starts with one of
    `executables` (or `ros2 run liver_sim <executable>`, `ros2 param set`)."""
    found = []
    for block in re.findall(r"^```[^\n]*\n(.*?)^```", text, flags=re.M | re.S):
        for line in block.replace("\\\n", " ").splitlines():
            found.append((re.sub(r"(^|\s)#.*", "", line).strip(), True))
    prose = re.sub(r"^```.*?^```", "", text, flags=re.M | re.S)
    found += [(" ".join(span.split()), False) for span in re.findall(r"`([^`]+)`", prose)]
    commands = []
    for line, block in found:
        line = re.sub(r"^ros2 run liver_sim ", "", line)
        if line.split(" ", 1)[0] in executables or line.startswith("ros2 param set "):
            commands.append((line, block))
    return commands


def tokens_of(command: str) -> list[str]:
    try:
        return shlex.split(command)
    except ValueError:
        return command.split()


def unbracketed(token: str) -> str:
    """`token` without the brackets of a synopsis (`[--json]`, `[--scale`, `F]]`); a list value keeps its own."""
    while token.startswith("[") and token.count("[") > token.count("]"):
        token = token[1:]
    while token.endswith("]") and token.count("]") > token.count("["):
        token = token[:-1]
    return "" if token in ("[", "]") else token
