"""pytest for mutmut: exit code 1 for every failure. mutmut 2 takes only 1 as killed, and pytest says 2 when a
mutant breaks an import; run in this process (no shell between), mutmut's timeout kills the tests themselves."""

from __future__ import annotations

import sys

import pytest

if __name__ == "__main__":
    sys.exit(0 if pytest.main(sys.argv[1:]) == 0 else 1)
