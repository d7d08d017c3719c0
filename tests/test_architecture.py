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
        names: list[str] = []
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names = [node.module] + [f"{node.module}.{a.name}" for a in node.names]
        for name in names:
            target = module_file(name)
            if target is not None and target != path:
                found.add(target)
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


def test_no_never_of_the_whiteboard_is_broken():
    board = json.loads((ROOT / "architecture-whiteboard.json").read_text())
    parts = {name: spec["is"] for name, spec in board["parts"].items()}
    files = [p for folder in FOLDERS for p in (ROOT / folder).rglob("*.py")]
    assert len(files) > 50
    graph = {p: imports_of(p) for p in files}
    owner = {p: part_of(p, parts) for p in files}
    broken = []
    for a, b, why in board["never"]:
        for start in (p for p in files if owner[p] == a):
            seen, stack = {start}, [start]
            while stack:
                for nxt in graph.get(stack.pop(), ()):
                    if nxt in seen:
                        continue
                    seen.add(nxt)
                    if owner.get(nxt) == b:
                        broken.append(f"{a} -> {b} ({why}): {start.relative_to(ROOT)} reaches {nxt.relative_to(ROOT)}")
                    elif owner.get(nxt) is None:
                        stack.append(nxt)
    assert not broken, "\n".join(broken)


def test_the_check_sees_a_broken_never(tmp_path):
    """The reader finds lazy imports through the namespace, so a never can fail."""
    path = ROOT / "spinefarm" / "coordinator" / "core.py"
    assert ROOT / "spinefarm" / "protocol" / "work.py" in imports_of(path)
    probe = tmp_path / "probe.py"
    probe.write_text("def f():\n    from spinefarm.worker.engines.bullet import BulletPhysics\n")
    assert imports_of(probe) == {ROOT / "spinefarm" / "worker" / "engines" / "bullet.py"}
