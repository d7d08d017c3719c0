"""Small modules and short functions: no module of the package over 400 lines, no function over 60 lines or 10
parameters. Compiled kernels (numba's @njit, @intrinsic) are left out: they are one loop over arrays, cut into
pieces only at the cost of calls in the hot path."""

from __future__ import annotations

import ast

from tests.test_architecture import FOLDERS, ROOT

MAX_MODULE_LINES = 400
MAX_FUNCTION_LINES = 60
MAX_PARAMETERS = 10
KERNEL_DECORATORS = {"njit", "intrinsic"}


def _decorator_name(node: ast.expr) -> str:
    target = node.func if isinstance(node, ast.Call) else node
    return target.attr if isinstance(target, ast.Attribute) else getattr(target, "id", "")


def oversized(source: str, name: str) -> list[str]:
    """What in one module's source breaks the limits, one line each."""
    found = []
    n_lines = len(source.splitlines())
    if n_lines > MAX_MODULE_LINES:
        found.append(f"{name}: {n_lines} lines (at most {MAX_MODULE_LINES})")
    for node in ast.walk(ast.parse(source, name)):
        if not isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
            continue
        if {_decorator_name(d) for d in node.decorator_list} & KERNEL_DECORATORS:
            continue
        lines = node.end_lineno - node.lineno + 1
        args = node.args
        params = [a.arg for a in (*args.posonlyargs, *args.args, *args.kwonlyargs)]
        n_params = len([p for p in params if p not in ("self", "cls")]) + bool(args.vararg) + bool(args.kwarg)
        if lines > MAX_FUNCTION_LINES:
            found.append(f"{name}:{node.lineno} {node.name}: {lines} lines (at most {MAX_FUNCTION_LINES})")
        if n_params > MAX_PARAMETERS:
            found.append(f"{name}:{node.lineno} {node.name}: {n_params} parameters (at most {MAX_PARAMETERS})")
    return found


def test_no_module_or_function_of_the_package_is_oversized():
    files = sorted(p for folder in FOLDERS for p in (ROOT / folder).rglob("*.py"))
    assert len(files) > 100
    found = [line for p in files for line in oversized(p.read_text(), p.relative_to(ROOT).as_posix())]
    assert not found, "\n".join(found)


def test_the_check_sees_a_long_function_many_parameters_and_a_long_module():
    body = "".join(f"    x{i} = {i}\n" for i in range(60))
    long_function = f"def long(a):\n{body}"
    assert oversized(long_function, "m.py") == ["m.py:1 long: 61 lines (at most 60)"]
    assert oversized(f"from numba import njit\n\n@njit(cache=True)\n{long_function}", "k.py") == []
    many = "def many(self, " + ", ".join(f"p{i}" for i in range(10)) + ", *rest):\n    pass\n"
    assert oversized(many, "m.py") == ["m.py:1 many: 11 parameters (at most 10)"]
    assert oversized("x = 1\n" * 401, "m.py") == ["m.py: 401 lines (at most 400)"]
