"""The architecture as drawn in architecture-whiteboard.json, held against the code's imports.

Each part is some files or folders; a "never" says no file of part A may import a file of part B, directly or
through files that belong to no part. Imports are read from the syntax tree (lazy imports inside functions
count); `spinefarm.a.b` is the file spinefarm/a/b.py (or the package spinefarm/a/b/).
"""

from __future__ import annotations

import ast
import json
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
FOLDERS = ("spinefarm",)


def module_file(dotted: str) -> Path | None:
    parts = dotted.split(".")
    if parts[0] != "spinefarm":
        return None
    base = ROOT.joinpath(*parts)
    for candidate in (base.with_suffix(".py"), base / "__init__.py"):
        if candidate.is_file():
            return candidate
    return None


def imports_of(path: Path) -> set[Path]:
    found: set[Path] = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        targets: list[Path | None] = []
        if isinstance(node, ast.Import):
            targets = [module_file(a.name) for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            # `from pkg import sub` takes the module sub; `from pkg import name` takes pkg's own name
            targets = [module_file(f"{node.module}.{a.name}") or module_file(node.module) for a in node.names]
        found.update(t for t in targets if t is not None and t != path)
    return found


def part_of(path: Path, parts: dict[str, list[str]]) -> str | None:
    rel = path.relative_to(ROOT).as_posix()
    best, best_len = None, -1
    for name, entries in parts.items():
        for entry in entries:
            hit = rel == entry or (entry.endswith("/") and rel.startswith(entry))
            if hit and len(entry) > best_len:
                best, best_len = name, len(entry)
    return best


def package_files() -> list[Path]:
    return [p for folder in FOLDERS for p in (ROOT / folder).rglob("*.py")]


def part_arrows(board: dict) -> dict[tuple[str, str], tuple[Path, Path]]:
    """Every (part A, part B) with a file of A importing one of B, directly or through files on no part, with
    one such pair of files."""
    parts = {name: spec["is"] for name, spec in board["parts"].items()}
    files = package_files()
    graph = {p: imports_of(p) for p in files}
    owner = {p: part_of(p, parts) for p in files}
    arrows: dict[tuple[str, str], tuple[Path, Path]] = {}
    for start in (p for p in files if owner[p] is not None):
        seen, stack = {start}, [start]
        while stack:
            for nxt in graph.get(stack.pop(), ()):
                if nxt in seen:
                    continue
                seen.add(nxt)
                if owner.get(nxt) is None:
                    stack.append(nxt)
                elif owner[nxt] != owner[start]:
                    arrows.setdefault((owner[start], owner[nxt]), (start, nxt))
    return arrows


def board() -> dict:
    return json.loads((ROOT / "architecture-whiteboard.json").read_text())


def test_no_never_of_the_whiteboard_is_broken():
    assert len(package_files()) > 50
    arrows = part_arrows(board())
    broken = [f"{a} -> {b} ({why}): {arrows[a, b][0].relative_to(ROOT)} reaches {arrows[a, b][1].relative_to(ROOT)}"
              for a, b, why in board()["never"] if (a, b) in arrows]
    assert not broken, "\n".join(broken)


def test_the_whiteboard_draws_every_arrow_the_code_has_and_no_other():
    found = part_arrows(board())
    drawn = {(a, b) for a, b, *_ in board()["arrows"]}
    undrawn = [f"{a} -> {b}: {found[a, b][0].relative_to(ROOT)} imports {found[a, b][1].relative_to(ROOT)}"
               for a, b in sorted(set(found) - drawn)]
    assert not undrawn, "\n".join(undrawn)
    assert not drawn - set(found), f"drawn, but no import runs so: {sorted(drawn - set(found))}"


def test_no_two_modules_import_each_other_even_through_others():
    """No import circle (type-only and lazy imports count): every module stands above all it imports."""
    graph = {p: imports_of(p) for p in package_files()}
    index: dict[Path, int] = {}
    low: dict[Path, int] = {}
    stack: list[Path] = []
    circles = []

    def visit(node: Path) -> None:  # Tarjan's strongly connected components
        index[node] = low[node] = len(index)
        stack.append(node)
        for nxt in graph.get(node, ()):
            if nxt not in index:
                visit(nxt)
                low[node] = min(low[node], low[nxt])
            elif nxt in stack:
                low[node] = min(low[node], index[nxt])
        if low[node] == index[node]:
            component = []
            while True:
                member = stack.pop()
                component.append(member.relative_to(ROOT).as_posix())
                if member == node:
                    break
            if len(component) > 1:
                circles.append(sorted(component))

    for node in graph:
        if node not in index:
            visit(node)
    assert not circles, circles


def test_the_check_sees_a_broken_never(tmp_path):
    """The reader finds lazy imports through the namespace, so a never can fail."""
    path = ROOT / "spinefarm" / "coordinator" / "core.py"
    assert ROOT / "spinefarm" / "protocol" / "work.py" in imports_of(path)
    probe = tmp_path / "probe.py"
    probe.write_text("def f():\n    from spinefarm.worker.engines.bullet import BulletPhysics\n")
    assert imports_of(probe) == {ROOT / "spinefarm" / "worker" / "engines" / "bullet.py"}
