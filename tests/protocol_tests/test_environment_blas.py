"""The record's BLAS part from a fresh process: the threads OpenBLAS was told to use (1, then 2), and nothing
looked up when numpy is not imported (protocol.environment: standard library only)."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np

CODE = "import json{}; from spinefarm.protocol.environment import environment_record; " \
       "print(json.dumps(environment_record()['blas']))"


def _blas(with_numpy: bool, threads: str) -> dict:
    env = {k: v for k, v in os.environ.items() if not k.endswith("_NUM_THREADS")}
    out = subprocess.run([sys.executable, "-c", CODE.format(", numpy" if with_numpy else "")], check=True,
                         capture_output=True, text=True, env={**env, "OPENBLAS_NUM_THREADS": threads}, timeout=120)
    return json.loads(out.stdout)


def test_the_blas_threads_are_those_openblas_was_told() -> None:
    one, two = _blas(True, "1"), _blas(True, "2")
    assert (one["threads"], two["threads"]) == (1, 2)  # the machine has 2 cores or more (CI and here)
    assert one["library"] == np.show_config(mode="dicts")["Build Dependencies"]["blas"]["name"]
    assert one["kernel"] and one["kernel"] == two["kernel"]


def test_without_numpy_nothing_is_looked_up() -> None:
    assert _blas(False, "1") == {"library": None, "version": None, "kernel": None, "threads": None}
