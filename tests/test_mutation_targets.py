"""`make mutation`'s lists stay true: every module and test file it names exists, and the functions a
restricted module is measured on are defined there (tests/mutation/lines.py finds their lines)."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.mutation.lines import function_lines
from tests.mutation.targets import FUNCTIONS, NO_JIT, TARGETS

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize("name", sorted(TARGETS))
def test_every_target_names_files_that_exist(name: str) -> None:
    module, tests = TARGETS[name]
    assert (ROOT / module).is_file()
    for t in tests + NO_JIT.get(name, ()):
        assert (ROOT / t.split("::")[0]).is_file(), t


def test_function_lines_by_hand() -> None:
    source = "import x\n\n\n@deco\ndef f():\n    return 1\n\n\nclass C:\n    def m(self):\n        pass\n"
    assert function_lines(source, ["f"]) == {4, 5, 6}
    assert function_lines(source, ["C.m"]) == {10, 11}
    assert function_lines(source, ["C"]) == {9, 10, 11}
    with pytest.raises(SystemExit, match="no function g"):
        function_lines(source, ["g"])


@pytest.mark.parametrize("name", sorted(FUNCTIONS))
def test_restricted_modules_name_functions_they_define(name: str) -> None:
    assert function_lines((ROOT / TARGETS[name][0]).read_text(), list(FUNCTIONS[name]))


def test_a_mutant_left_in_the_copy_is_replaced_by_the_module_as_copied_not_as_the_checkout_has_it_now(tmp_path):
    from tests.mutation.main import restore

    module = "spinefarm/coordinator/ladder/ladder.py"
    copied = tmp_path / module
    copied.parent.mkdir(parents=True)
    original = b"x = 1\n"
    copied.write_bytes(b"x = 2\n")                       # a mutant an ended mutmut left behind
    (tmp_path / f"{module}.bak").write_bytes(original)
    restore(tmp_path, module, original)
    assert copied.read_bytes() == original != (ROOT / module).read_bytes()
    assert not (tmp_path / f"{module}.bak").exists()
