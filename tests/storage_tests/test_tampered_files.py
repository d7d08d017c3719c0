"""Tampered files: a run file whose parameter names do not fit its columns, a status file with a malformed
worker entry. One-line errors from export, load_run and --resume; /runs answers for the other runs and names
what it set aside."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest

import spinefarm
from spinefarm.protocol.errors import StorageError
from spinefarm.storage.status import status_path
from tests.coordinator_tests.procs import ROOT
from tests.coordinator_tests.test_run_file_faults import digest, finished_run

MISFIT = "does not fit together"


def with_names(src: Path, dst: Path, names: list[str], run_id: str) -> Path:
    shutil.copy(src, dst)
    with h5py.File(dst, "r+") as f:
        f.attrs["param_names"] = np.array(names, dtype=h5py.string_dtype())
        f.attrs["run_id"] = run_id
    return dst


@pytest.fixture
def runs(tmp_path: Path) -> Path:
    d = tmp_path / "runs"
    d.mkdir()
    finished_run(tmp_path / "src.h5", n=12)  # sphere:4, 12 complete trials of 40
    with_names(tmp_path / "src.h5", d / "good.h5", ["x0", "x1", "x2", "x3"], "good")
    with_names(tmp_path / "src.h5", d / "fewer.h5", ["x0", "x1", "x2"], "fewer")        # 3 names, 4 columns
    with_names(tmp_path / "src.h5", d / "more.h5", ["a", "b", "c", "d", "e"], "more")   # 5 names, 4 columns
    with_names(tmp_path / "src.h5", d / "sidecar.h5", ["x0", "x1", "x2", "x3"], "sidecar")
    with_names(tmp_path / "src.h5", d / "sampler.h5", ["x0", "x1", "x2", "x3"], "sampler")
    with h5py.File(d / "sampler.h5", "r+") as f:
        f.attrs["sampler"] = "[1, 2]"  # valid JSON, and a valid file, but no sampler description
    status_path(d / "sidecar.h5").write_text(json.dumps(
        {"state": "running", "updated_at_unix_s": 1.0, "workers": [{"worker_id": 7, "alive": "maybe"}]}))
    with_names(tmp_path / "src.h5", d / "state.h5", ["x0", "x1", "x2", "x3"], "state")
    status_path(d / "state.h5").write_text(json.dumps({"state": "hacked", "updated_at_unix_s": 1.0}))
    return d


def one_line_error(r: subprocess.CompletedProcess, command: str) -> str:
    assert r.returncode == 2, r.stderr
    assert "Traceback" not in r.stderr, r.stderr
    lines = [ln for ln in r.stderr.splitlines() if ln.startswith(f"spinefarm {command}: error: ")]
    assert len(lines) == 1, r.stderr
    return lines[0]


@pytest.mark.parametrize("name", ["fewer.h5", "more.h5"])
def test_export_and_load_run_name_the_misfit(runs: Path, name: str):
    r = subprocess.run([sys.executable, "-m", "spinefarm", "export", str(runs / name), "--csv", str(runs / "o.csv")],
                       cwd=ROOT, capture_output=True, text=True, timeout=60)
    line = one_line_error(r, "export")
    assert MISFIT in line and "param_names" in line and "/trials/params columns 4" in line
    assert not (runs / "o.csv").exists()
    with pytest.raises(StorageError, match=MISFIT) as exc:
        spinefarm.load_run(runs / name)
    assert "\n" not in str(exc.value)


def test_resume_refuses_the_misfit_and_leaves_it_untouched(runs: Path):
    before = digest(runs / "fewer.h5")
    r = subprocess.run([sys.executable, "-m", "spinefarm", "search", "--resume", str(runs / "fewer.h5"), "--workers",
                        "1", "--api-port", "-1", "--quiet"], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert MISFIT in one_line_error(r, "search")
    assert digest(runs / "fewer.h5") == before


def test_runs_answers_for_the_others_and_names_what_it_set_aside(runs: Path):
    from spinefarm.api.app import create_app
    from tests.http_server import served

    with served(create_app(runs_dir=runs)) as client:
        listed = client.get("/runs")
        assert listed.status_code == 200, listed.text
        by_id = {r["run_id"]: r for r in listed.json()}
        assert sorted(by_id) == ["good", "sidecar", "state"]
        assert by_id["state"]["state"] == "stopped" and "state: Input should be" in by_id["state"]["status_file_error"]
        assert by_id["good"]["status_file_error"] is None and by_id["good"]["trials_complete"] == 12
        why = by_id["sidecar"]["status_file_error"]
        assert "malformed" in why and "workers.0" in why and str(status_path(runs / "sidecar.h5")) in why
        assert by_id["sidecar"]["state"] == "stopped"  # from the file alone: no writer, 12 of 40 done
        assert by_id["sidecar"]["workers"] == []
        assert client.get("/runs/sidecar").status_code == 200
        damaged = {Path(d["file"]).name: d["reason"] for d in client.get("/damaged-files").json()}
        assert sorted(damaged) == ["fewer.h5", "more.h5", "sampler.h5"]
        assert MISFIT in damaged["fewer.h5"] and MISFIT in damaged["more.h5"]
        assert "its status cannot be read now" in damaged["sampler.h5"]
        one = client.get("/runs/sampler")
        assert one.status_code == 409 and "cannot show run file" in one.json()["detail"]["message"]
        assert client.get("/runs/fewer").status_code == 404


@pytest.mark.parametrize("instances", ['"not a list"', "[1, 2]", '[{"how": "create"}]', "{"])
def test_a_tampered_instance_history_is_a_one_line_error(tmp_path: Path, instances: str):
    finished_run(tmp_path / "src.h5", n=3)
    with h5py.File(tmp_path / "src.h5", "r+") as f:
        assert json.loads(f.attrs["instances"])[0]["how"] == "create"   # the history the file was written with
        f.attrs["instances"] = instances
    with pytest.raises(StorageError, match="unreadable metadata") as exc:
        spinefarm.load_run(tmp_path / "src.h5")
    assert "\n" not in str(exc.value) and "instances" in str(exc.value)
