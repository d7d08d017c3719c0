"""One judged speed: the report's verdict, its cost line and the API give the same figure for a judged set."""

from __future__ import annotations

from spinefarm.api.app import create_app
from spinefarm.cli.report import _judge_figures, verdict_text
from spinefarm.storage.hdf5 import Hdf5Storage
from tests.api_tests.test_api import write_run
from tests.http_server import served


def test_the_judged_speed_is_one_figure_in_report_and_api(tmp_path):
    s = write_run(tmp_path / "j.h5", run_id="run-j", keep_open=True)  # every trial simulated 5 s
    s.set_verification(1, "judged", 0.6, ratio=1 / 0.6)  # 0.6 m judged over 5 s: 12 cm/s (the screen: 2 cm/s)
    s.set_verification(2, "holds", 1.5)  # 1.5 m over 5 s: 30 cm/s
    s.flush()
    s.close()
    store = Hdf5Storage.open_read(tmp_path / "j.h5")
    try:
        judged, held = store.trial(1), store.trial(2)
        assert "0.6 m, 12 cm/s" in verdict_text(judged, "mujoco")
        assert _judge_figures(store, judged, 0.6)[0] == 12.0
        assert _judge_figures(store, held, 1.5)[0] == 30.0
    finally:
        store.close()
    with served(create_app(runs_dir=tmp_path)) as c:
        speeds = [c.get(f"/runs/run-j/trials/{i}").json()["verification"]["judged_speed_cm_s"] for i in (0, 1, 2)]
        one = c.get("/runs/run-j/trials/1").json()["verification"]
    assert speeds == [None, 12.0, 30.0]  # trial 0 was not judged: no judged speed
    assert one["judge_distance_m"] == one["fine_step_distance_m"] == 0.6
