"""Two rules of the design (DESIGN.md, "One parameter's walk, sampler to engine"), read from the syntax tree of
every module under spinefarm/: no module is entered only to be passed through (it re-exports, or a function of it
hands its own parameters unchanged to someone else's function), and no call goes back up a layer from an engine
into the loop (an engine never calls a function it was handed)."""

from __future__ import annotations

import ast
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
ENGINES = ROOT / "spinefarm" / "worker" / "engines"


def modules() -> list[Path]:
    return sorted((ROOT / "spinefarm").rglob("*.py"))


def parameters(fn: ast.FunctionDef | ast.AsyncFunctionDef) -> list[str]:
    args = fn.args
    names = [a.arg for a in args.posonlyargs + args.args + args.kwonlyargs]
    names += [a.arg for a in (args.vararg, args.kwarg) if a is not None]
    return [n for n in names if n not in ("self", "cls")]


def forwards(fn: ast.FunctionDef | ast.AsyncFunctionDef, own: set[str]) -> bool:
    """One call (returned or not) of a function this module did not define, or of a method of a parameter,
    given exactly the function's own parameters, each unchanged: the function adds nothing but a hop."""
    body = fn.body[1:] if ast.get_docstring(fn) is not None else fn.body
    if len(body) != 1 or not isinstance(body[0], ast.Return | ast.Expr) or not isinstance(body[0].value, ast.Call):
        return False
    call, params = body[0].value, parameters(fn)
    handed = [a.value if isinstance(a, ast.Starred) else a for a in call.args] + [k.value for k in call.keywords]
    if not params or not all(isinstance(a, ast.Name) for a in handed):
        return False
    passed = [a.id for a in handed]
    func = call.func
    if isinstance(func, ast.Attribute) and isinstance(func.value, ast.Name) and func.value.id in params:
        passed.append(func.value.id)  # engine.advance(...) inside advance(engine, ...): the receiver is handed on
    elif isinstance(func, ast.Name) and func.id in own:
        return False  # a call of the module's own code: a convenience form, not a hop elsewhere
    return sorted(passed) == sorted(params)


def pass_throughs(path: Path) -> list[str]:
    tree = ast.parse(path.read_text(), str(path))
    own = {n.name for n in tree.body if isinstance(n, ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef)}
    found = []
    top = [n for n in tree.body if not (isinstance(n, ast.Expr) and isinstance(n.value, ast.Constant))]
    top = [n for n in top if not (isinstance(n, ast.ImportFrom) and n.module == "__future__")]
    imports = [n for n in top if isinstance(n, ast.Import | ast.ImportFrom)]
    rest = [n for n in top if n not in imports and not _is_all(n)]
    if imports and not rest:
        found.append(f"{path.relative_to(ROOT)}: only re-exports")
    for node in tree.body:  # a module's own functions (a method handing on to a member is composition), and
        # not a decorated one (a route or a command: the framework's entry, not a hop between modules)
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef) and not node.decorator_list \
                and forwards(node, own):
            found.append(f"{path.relative_to(ROOT)}:{node.lineno} {node.name} only forwards its parameters")
    return found


def _is_all(node: ast.stmt) -> bool:
    return isinstance(node, ast.Assign) and any(isinstance(t, ast.Name) and t.id == "__all__" for t in node.targets)


def callbacks(path: Path) -> list[str]:
    """Calls of a function an engine's method was handed (a parameter called, or a Callable parameter)."""
    found = []
    for fn in ast.walk(ast.parse(path.read_text(), str(path))):
        if not isinstance(fn, ast.FunctionDef | ast.AsyncFunctionDef):
            continue
        params = set(parameters(fn))
        for arg in fn.args.posonlyargs + fn.args.args + fn.args.kwonlyargs:
            if arg.annotation is not None and "Callable" in ast.unparse(arg.annotation):
                found.append(f"{path.relative_to(ROOT)}:{fn.lineno} {fn.name} takes a callable {arg.arg}")
        for node in ast.walk(fn):
            if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id in params:
                found.append(f"{path.relative_to(ROOT)}:{node.lineno} {fn.name} calls its parameter {node.func.id}")
    return found


# pass-throughs that predate the rule, in parts being reworked apart from the worker's; the list only shrinks
# (a new one fails, and so does one that is gone but still listed)
KNOWN_PASS_THROUGHS = {
    "spinefarm/api/deps.py:22 run_path only forwards its parameters",
    "spinefarm/coordinator/samplers/__init__.py: only re-exports",
    "spinefarm/storage/__init__.py: only re-exports",
}


def test_no_module_is_only_passed_through():
    found = {hit for path in modules() for hit in pass_throughs(path)}
    assert found - KNOWN_PASS_THROUGHS == set(), sorted(found - KNOWN_PASS_THROUGHS)
    known = {k.split(" ")[0].split(":")[0] for k in KNOWN_PASS_THROUGHS - found}
    assert not known, f"no longer a pass-through, take it off KNOWN_PASS_THROUGHS: {sorted(known)}"


def test_no_engine_calls_back_into_the_loop():
    assert list(ENGINES.glob("*.py")), ENGINES
    found = [hit for path in sorted(ENGINES.glob("*.py")) for hit in callbacks(path)]
    assert not found, found


HOP = '''
def advance(engine, run, n_steps, active, horizon_steps):
    """n_steps through the engine."""
    engine.advance(run, n_steps, active, horizon_steps)
'''
RE_EXPORT = '"""Names from elsewhere."""\nfrom spinefarm.protocol.run import RunConfig\n\n__all__ = ["RunConfig"]\n'
CALLBACK = '''
class Physics:
    def advance(self, run, n_steps, active):
        run(n_steps, active)
'''


def test_the_checks_see_what_they_forbid(tmp_path: Path, monkeypatch):
    """The checks on the forms the design names: the old loop.advance hop, a module of re-exports, and the
    engine's old advance(run, ...) that called the loop's steps."""
    monkeypatch.setattr(sys.modules[__name__], "ROOT", tmp_path)
    for name, text in (("hop.py", HOP), ("reexport.py", RE_EXPORT), ("physics.py", CALLBACK)):
        (tmp_path / name).write_text(text)
    assert pass_throughs(tmp_path / "hop.py") == ["hop.py:2 advance only forwards its parameters"]
    assert pass_throughs(tmp_path / "reexport.py") == ["reexport.py: only re-exports"]
    assert callbacks(tmp_path / "physics.py") == ["physics.py:4 advance calls its parameter run"]
    (tmp_path / "own.py").write_text("def run_trial(m, p):\n    return simulate(m, p)\n\n\ndef simulate(m, p):\n"
                                     "    return m + p\n")
    assert pass_throughs(tmp_path / "own.py") == []
