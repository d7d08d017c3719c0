"""pytest for mutmut: exit code 1 for every failure. mutmut 2 takes only 1 as killed, and pytest says 2 when a
mutant breaks an import; run in this process (no shell between), mutmut's timeout kills the tests themselves.

    python -m tests.mutation.pytest_exit [--no-jit PYTEST_ARGS... --then] PYTEST_ARGS...

With `--no-jit`, the first arguments run with NUMBA_DISABLE_JIT=1 (a numba kernel's mutant is run as Python,
no compilation: seconds), and only if they pass the rest run compiled, in the same process id (exec), so
mutmut's timeout still ends them."""

from __future__ import annotations

import os
import sys

NO_JIT, THEN = "--no-jit", "--then"


def main(argv: list[str]) -> int:
    if argv[:1] == [NO_JIT]:
        if THEN not in argv:
            raise SystemExit(f"pytest_exit: {NO_JIT} needs {THEN} before the compiled stage's arguments, "
                             f"got {' '.join(argv)}")
        cut = argv.index(THEN)
        os.environ["NUMBA_DISABLE_JIT"] = "1"  # read when numba is first imported, so before pytest's conftest
        import pytest

        if pytest.main(argv[1:cut]) != 0:
            return 1
        env = {k: v for k, v in os.environ.items() if k != "NUMBA_DISABLE_JIT"}
        sys.stdout.flush()
        os.execve(sys.executable, [sys.executable, "-m", "tests.mutation.pytest_exit", *argv[cut + 1:]], env)
    import pytest

    return 0 if pytest.main(argv) == 0 else 1


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
