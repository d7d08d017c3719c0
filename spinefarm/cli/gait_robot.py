"""The robot a gait file names, for `spinefarm trial --params GAIT.json` given no robot of its own."""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

from spinefarm.protocol.errors import ParameterError


def gait_robot(path: Path) -> Any:
    """A gait file's robot: its `morphology_spec` mapping when it records one (exact), else its `morphology`
    (a built-in name, a spec mapping, or a .yaml spec path, relative to the gait file when not found here).
    Says on standard error which robot it took; a file naming none is refused in one line."""
    data = json.loads(path.read_text())  # load_params_file has already refused what is no JSON object
    robot = data.get("morphology_spec") or data.get("morphology")
    if isinstance(robot, str) and robot.strip():
        yaml_path = Path(robot)
        if yaml_path.suffix.lower() in (".yaml", ".yml") and not yaml_path.exists() and not yaml_path.is_absolute():
            robot = str(path.parent / yaml_path)
        told = robot
    elif isinstance(robot, dict) and robot:
        told = f"the spec it records ({robot.get('name', 'unnamed')})"
    else:
        raise ParameterError("no robot to run: the gait file names none", received=f"{path} (morphology: "
                             f"{json.dumps(robot)})", expected="a robot argument, --run RUN.h5, or a gait file "
                             "with \"morphology\": a built-in name or spec")
    print(f"robot: {told}, from {path}", file=sys.stderr, flush=True)
    return robot
