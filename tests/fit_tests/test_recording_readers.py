"""Every recording reader round-trips through the spinefarm format, and a malformed recording is refused with
one line naming what was found and what was expected."""

from __future__ import annotations

import gzip
from pathlib import Path

import numpy as np
import pytest

from spinefarm.cli.main import main
from spinefarm.worker.fit.readers import read_recording
from spinefarm.worker.fit.recording import Recording, RecordingError

NTRT = Path("/work/shared/ntrt-recordings")
NTRT_RUN = NTRT / "TetraSpine" / "random-00"


def _same(a: Recording, b: Recording) -> None:
    for name in ("time_s", "position_m", "quat_wxyz", "string_length_m", "rest_length_m", "tension_n"):
        x, y = getattr(a, name), getattr(b, name)
        assert (x is None) == (y is None), name
        if x is not None:
            assert np.array_equal(x, y), name
    assert a.drive == b.drive and a.scene == b.scene


def _round_trip(rec: Recording, tmp_path: Path) -> Recording:
    rec.save(tmp_path / "copy.npz")
    again = read_recording(tmp_path / "copy.npz")
    _same(rec, again)
    return again


@pytest.mark.skipif(not NTRT_RUN.exists(), reason="NTRT's recordings are not on this machine")
def test_ntrt_reader_converts_units_and_ground(tmp_path):
    rec = read_recording(NTRT_RUN)
    assert rec.n_segments == 3 and rec.n_strings == 12 and len(rec.time_s) == 1001
    # the CSV's first row (README: cm, Y up, NTRT's ground top at 1.5 cm; ours at 0.5 cm)
    assert rec.position_m[0, 0] == pytest.approx([0.0, (14.090743 - 1.0) / 100, 0.78405593])
    assert rec.quat_wxyz[0, 2] == pytest.approx([1, 0, 0, 0])
    # the second row's string 2: 27.938806 cm long, rest 27.933639 cm, tension 51.667568 kg cm/s^2 = 0.5167 N
    assert rec.string_length_m[1, 2] == pytest.approx(0.27938806)
    assert rec.rest_length_m[1, 2] == pytest.approx(0.27933639)
    assert rec.tension_n[1, 2] == pytest.approx(0.51667568)
    assert rec.drive == {"kind": "rest_lengths"}
    _round_trip(rec, tmp_path)


def test_trial_record_reader(tmp_path):
    out = tmp_path / "t.npz"
    assert main(["trial", "tetraspine-ntrt", "--random-seed", "2", "--duration", "0.1", "--record", str(out),
                 "--json"]) == 0
    with np.load(out) as z:
        poses = z["poses"]
    rec = read_recording(out)
    assert rec.position_m == pytest.approx(poses[:, :, :3] / 100)
    assert rec.quat_wxyz[:, :, 0] == pytest.approx(poses[:, :, 6])  # w last in the trial's poses
    assert rec.drive["kind"] == "controller" and len(rec.drive["params"]) > 10
    assert rec.morphology == "tetraspine-ntrt"
    _round_trip(rec, tmp_path)


def _pose_csv(path: Path, rows: list[list[float]], header: str | None = None) -> Path:
    head = header or ("time_s,seg0_x_mm,seg0_y_mm,seg0_z_mm,seg0_qw,seg0_qx,seg0_qy,seg0_qz,"
                      "seg1_x_cm,seg1_y_cm,seg1_z_cm,seg1_qw,seg1_qx,seg1_qy,seg1_qz,str0_rest_mm")
    path.write_text(head + "\n" + "\n".join(",".join(str(v) for v in r) for r in rows) + "\n")
    return path


ROWS = [[0.0, 100, 50, -20, 1, 0, 0, 0, 30, 5, 2, 1, 0, 0, 0, 250],
        [0.005, 101, 51, -21, 0, 1, 0, 0, 31, 6, 3, 0, 0, 1, 0, 249]]


def test_pose_csv_reader_units(tmp_path):
    rec = read_recording(_pose_csv(tmp_path / "mocap.csv", ROWS))
    assert rec.position_m[1, 0] == pytest.approx([0.101, 0.051, -0.021])  # mm
    assert rec.position_m[1, 1] == pytest.approx([0.31, 0.06, 0.03])  # cm
    assert rec.quat_wxyz[1, 1] == pytest.approx([0, 0, 1, 0])
    assert rec.rest_length_m[:, 0] == pytest.approx([0.25, 0.249])
    assert rec.time_s == pytest.approx([0.0, 0.005])
    _round_trip(rec, tmp_path)


@pytest.mark.parametrize(("rows", "header", "message"), [
    ([ROWS[1], ROWS[0]], None, "time is not increasing; received 't = 0 s at row 1 after 0.005 s'"),
    ([ROWS[0], [*ROWS[1][:2], "nan", *ROWS[1][3:]]], None,
     "position_m holds a non-finite value; received 'nan at row 1'"),
    (ROWS, "time_s,seg0_x_ft,seg0_y_ft,seg0_z_ft,seg0_qw,seg0_qx,seg0_qy,seg0_qz,seg1_x_cm,seg1_y_cm,seg1_z_cm,"
           "seg1_qw,seg1_qx,seg1_qy,seg1_qz,str0_rest_mm",
     "column seg0_x_ft has an unknown length unit; received 'ft'"),
    ([r[:4] + r[5:] for r in ROWS], "time_s,seg0_x_mm,seg0_y_mm,seg0_z_mm,seg0_qx,seg0_qy,seg0_qz,seg1_x_cm,seg1_y_cm,"
     "seg1_z_cm,seg1_qw,seg1_qx,seg1_qy,seg1_qz,str0_rest_mm", "missing column; received 'seg0_qw'"),
    ([ROWS[0], [*ROWS[1][:4], 2, *ROWS[1][5:]]], None, "an orientation is not a unit quaternion; received 'norm 2.236"),
])
def test_malformed_pose_csv_one_line(tmp_path, rows, header, message):
    with pytest.raises(RecordingError) as err:
        read_recording(_pose_csv(tmp_path / "bad.csv", rows, header))
    assert message in str(err.value) and "\n" not in str(err.value) and "expected" in str(err.value)


def test_recording_of_another_robot_refused(tmp_path):
    rec = read_recording(_pose_csv(tmp_path / "two.csv", ROWS))
    with pytest.raises(RecordingError, match="does not fit tetraspine-ntrt; received '2 segments'; expected 3 seg"):
        rec.check_robot(3, 12, "tetraspine-ntrt")
    with pytest.raises(RecordingError, match="received '1 strings'; expected 12 strings"):
        rec.check_robot(2, 12, "tetraspine-ntrt")


@pytest.mark.skipif(not NTRT_RUN.exists(), reason="NTRT's recordings are not on this machine")
def test_ntrt_folder_missing_columns(tmp_path):
    folder = tmp_path / "run"
    folder.mkdir()
    (folder / "model-meta.txt").write_text((NTRT_RUN / "model-meta.txt").read_text())
    with gzip.open(NTRT_RUN / "trajectory.csv.gz", "rt") as fh:
        lines = fh.read().splitlines()[:5]
    cut = [",".join(line.split(",")[:-3]) for line in lines]  # the last string's three columns gone
    with gzip.open(folder / "trajectory.csv.gz", "wt") as fh:
        fh.write("\n".join(cut) + "\n")
    with pytest.raises(RecordingError, match=r"missing columns; received 'm11_len, m11_rest, m11_tension'"):
        read_recording(folder)
