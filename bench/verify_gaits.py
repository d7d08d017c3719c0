"""The shipped gaits under the search's own verification: the trial at the default step, again at a 4x finer step,
and at the finer step with 10 % more ground friction and a 0.01 cm start jitter (`search --verify-perturb`).

    python bench/verify_gaits.py                      # every gait in examples/gaits
    python bench/verify_gaits.py --gaits tetraspine,ribbed

Prints one JSON object: per gait the three distances and the relative changes of the other two against the
default step's (docs/results.md, "Side by side": its "fine step" and "perturbed" columns).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from spinefarm.worker.tools.verify import VerifySettings, verify_trial  # noqa: E402
from spinefarm.worker.trial.simulation import TrialConfig, simulate  # noqa: E402


def check(gait_file: Path) -> dict:
    gait = json.loads(gait_file.read_text())
    robot, params, controller = gait["morphology"], gait["params"], gait.get("controller")
    base = simulate(robot, params, TrialConfig(), 0, controller=controller).result
    v = verify_trial(robot, params, TrialConfig(), 0, base.distance_m, VerifySettings(perturb=True),
                     controller=controller)
    return {"distance_m": base.distance_m, "fine_distance_m": v.fine_distance_m, "fine_dt_s": v.fine_dt_s,
            "perturbed_distance_m": v.perturbed_distance_m,
            "fine_change": v.fine_distance_m / base.distance_m - 1,
            "perturbed_change": v.perturbed_distance_m / base.distance_m - 1,
            "verdict": str(v.verdict), "reason": v.reason, "tolerance": v.tolerance,
            "tolerance_source": v.tolerance_source}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--gaits", default=None, help="comma-separated gait names (default: every file in examples/gaits)")
    args = ap.parse_args()
    folder = ROOT / "examples" / "gaits"
    names = args.gaits.split(",") if args.gaits else sorted(p.stem for p in folder.glob("*.json"))
    print(json.dumps({"benchmark": "verify_gaits", "gaits": {n: check(folder / f"{n}.json") for n in names}}))


if __name__ == "__main__":
    main()
