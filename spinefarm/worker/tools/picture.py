"""The gait picture of a stored trial: re-simulate it as the run did (or read its recorded motion, JOB's
motion_file) and draw the `render` strip.

Run as `python -m spinefarm.worker.tools.picture JOB.json OUT.png` (the API calls it in a subprocess, so a server
without the simulator still serves everything else). JOB holds morphology (a Morphology.to_dict()),
controller, trial_config, params_unit, seed and frames.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any


def render_motion_file(job: dict[str, Any], out: str | Path) -> Path:
    """The strip drawn from an already recorded motion (worker/tools/motion.py's JSON): no simulation."""
    from spinefarm.robot.codesign import job_robot
    from spinefarm.worker.tools.motion import motion_record
    from spinefarm.worker.tools.render import frames_from_record, render

    morph, _ = job_robot(job)  # a co-designed trial's own body
    motion = json.loads(Path(job["motion_file"]).read_text())
    frames = frames_from_record(motion_record(motion), int(job.get("frames", 6)), motion["n_bodies"],
                                len(motion["strings"]))
    r = motion.get("result") or {}
    fig = lambda k: "–" if r.get(k) is None else f"{r[k]:.3g}"  # noqa: E731
    title = (f"{job.get('title', morph.name)}: {fig('distance_m')} m, {fig('speed_cm_s')} cm/s, COT {fig('cot')}"
             + (f" ({r['reason']})" if r.get("reason") else ""))
    return render(morph, frames, out, title=title)


def render_trial(job: dict[str, Any], out: str | Path) -> Path:
    from spinefarm.robot.codesign import job_robot
    from spinefarm.worker.tools.render import frames_from_record, render
    from spinefarm.worker.trial.simulation import TrialConfig, simulate

    if job.get("motion_file"):
        return render_motion_file(job, out)
    morph, unit = job_robot(job)  # a co-designed trial's own body
    base = dict(job["trial_config"])
    duration = float(base.get("duration_s") or morph.duration_s)
    base["record_every_s"] = max(0.01, duration / 200)
    outcome = simulate(morph, unit, TrialConfig.from_dict(base),
                       int(job["seed"]), controller=job.get("controller"))
    record = outcome.trajectory.arrays() if outcome.trajectory is not None else {}
    frames = frames_from_record(record, int(job.get("frames", 6)), morph.structure.n_segments,
                                len(morph.structure.strings))
    r = outcome.result
    title = (f"{job.get('title', morph.name)}: {r.distance_m:.3g} m, {r.speed_cm_s:.3g} cm/s, COT {r.cot:.3g}"
             + ("" if r.ok else f" ({r.reason})"))
    return render(morph, frames, out, title=title)


def main(argv: list[str]) -> int:
    from spinefarm.protocol.errors import SpinefarmError

    if len(argv) != 2:
        print("usage: python -m spinefarm.worker.tools.picture JOB.json OUT.png", file=sys.stderr)
        return 2
    try:
        render_trial(json.loads(Path(argv[0]).read_text()), argv[1])
    except SpinefarmError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
