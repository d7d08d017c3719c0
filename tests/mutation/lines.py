"""mutmut over only some functions of a module: for a module whose every mutant would take too long here, the
functions behind a documented promise (tests/mutation/targets.py's FUNCTIONS).

    python -m tests.mutation.lines MODULE NAME[,NAME...] -- MUTMUT_RUN_ARGS...

A NAME is a function, a class (all its methods) or `Class.method`. mutmut 2 can restrict a run to the lines a
patch adds; the lines of the named functions are handed to it in place of a patch file (no diff is read)."""

from __future__ import annotations

import ast
import sys
from pathlib import Path


def function_lines(source: str, names: list[str]) -> set[int]:
    """The line numbers of the named functions and classes, decorators and bodies included."""
    wanted, found, lines = set(names), set(), set()

    def visit(node: ast.AST, prefix: str) -> None:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
                name = prefix + child.name
                if name in wanted:
                    found.add(name)
                    first = min([child.lineno, *(d.lineno for d in child.decorator_list)])
                    lines.update(range(first, child.end_lineno + 1))
                if isinstance(child, ast.ClassDef):
                    visit(child, name + ".")

    visit(ast.parse(source), "")
    if wanted - found:
        raise SystemExit(f"mutation: no function {', '.join(sorted(wanted - found))} in the module; "
                         "expected a function, a class or Class.method defined there")
    return lines


def main(argv: list[str]) -> int:
    module, names, sep, *rest = argv
    if sep != "--":
        raise SystemExit(f"mutation: expected MODULE NAMES -- MUTMUT_RUN_ARGS, got {' '.join(argv[:3])}")
    lines = function_lines(Path(module).read_text(), names.split(","))
    import mutmut.__main__ as cli

    cli.read_patch_data = lambda _path: {str(Path(module)): lines}
    sys.argv = ["mutmut", *rest, "--use-patch-file", "(functions)"]
    return cli.climain()


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
