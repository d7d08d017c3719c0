"""The short recorded trial that `spinefarm render` draws (a strip or a motion): simulated from --params or
random parameters, or read back from a --record file."""

from __future__ import annotations

import argparse
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from spinefarm.protocol.errors import ConfigError


def load_record(path: Path, morph_name: str) -> dict[str, np.ndarray]:
    try:
        with np.load(path, allow_pickle=False) as data:
            record = {k: data[k] for k in data.files}
    except (OSError, ValueError) as exc:
        raise ConfigError("cannot read the trajectory file", received=str(path),
                          expected="an .npz written by `spinefarm trial --record`") from exc
    stored = str(record.get("morphology", morph_name))
    if stored != morph_name:
        raise ConfigError("the trajectory was recorded on another morphology", received=stored,
                          expected=morph_name)
    return record


def _params(morph: Any, path: Path | None, seed: int) -> tuple[Any, str | None]:
    from spinefarm.worker.trial.simulation import random_unit_params

    if path is None:
        return random_unit_params(morph, seed), None
    from spinefarm.worker.tools.replay import PUBLISHED, parameter_folder

    if path.is_dir() or str(path) in PUBLISHED:
        from spinefarm.worker.tools.replay import read_parameter_set, unit_params

        return unit_params(morph, read_parameter_set(parameter_folder(path))), "ntrt"
    from spinefarm.cli.sim_commands import load_params_file

    return load_params_file(path)


def simulate_recorded(args: argparse.Namespace, morph: Any, every_s: Callable[[float], float]
                      ) -> tuple[Any, dict[str, np.ndarray]]:
    """(outcome, recorded arrays) of the short trial `render` draws: --params (else random parameters from
    --random-seed), --duration (else at most 5 s), --engine, --motor-model, recorded every every_s(duration)
    seconds; saved to --record when given."""
    from spinefarm.worker.trial.simulation import TrialConfig, simulate

    params, controller = _params(morph, args.params, args.random_seed)
    duration = args.duration or min(morph.duration_s, 5.0)
    overrides: dict[str, Any] = {"duration_s": duration, "record_every_s": every_s(duration),
                                 "controller": controller}
    if args.motor_model:
        overrides["motor_model"] = args.motor_model
    if args.engine:
        overrides["engine"] = args.engine
    outcome = simulate(morph, params, TrialConfig(**overrides), args.random_seed)
    record = outcome.trajectory.arrays() if outcome.trajectory else {}
    if args.record is not None:
        np.savez_compressed(args.record, **record, morphology=morph.name)
    return outcome, record
