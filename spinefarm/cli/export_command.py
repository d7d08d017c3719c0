"""`spinefarm export`: a run file as CSV or Parquet, its best trials, its Pareto front or a gait file."""

from __future__ import annotations

import argparse
import sys
from typing import Any

from spinefarm.cli import checks
from spinefarm.protocol.errors import ConfigError


def cmd_export(args: argparse.Namespace) -> int:
    from spinefarm.storage.export import best_table, write_csv
    from spinefarm.storage.hdf5 import Hdf5Storage

    if all(v is None for v in (args.csv, args.best, args.pareto, args.parquet, args.gait, args.spec)):
        raise ConfigError("nothing to export", expected="--csv [OUT.csv], --parquet OUT.parquet, --best K, "
                          "--pareto [OUT.csv], --gait OUT.json and/or --spec OUT.yaml")
    if args.spec is not None:
        checks.output_path("--spec", args.spec, (".yaml", ".yml"))
    if args.csv not in (None, "-"):
        checks.output_path("--csv", args.csv, (".csv",))
    if args.pareto not in (None, "-"):
        checks.output_path("--pareto", args.pareto, (".csv",))
    if args.parquet is not None:
        checks.output_path("--parquet", args.parquet, (".parquet",))
    if args.gait is not None:
        checks.output_path("--gait", args.gait, (".json",))
    checks.at_least("--best", args.best, 1, "K best trials")
    storage = Hdf5Storage.open_read(args.file)
    if args.parquet is not None:
        _write_parquet(args.file, args.parquet)
    if args.csv is not None:
        if args.csv == "-":
            write_csv(storage, sys.stdout)
        else:
            with open(args.csv, "w", newline="") as fh:
                write_csv(storage, fh)
            print(f"wrote {storage.n_trials()} trials to {args.csv}", file=sys.stderr)
    if args.best is not None:
        if args.best < 1:
            raise ConfigError("--best out of range", received=args.best, expected="K >= 1")
        print(best_table(storage, args.best))
    if args.pareto is not None:
        ids = storage.pareto_ids()
        if args.pareto == "-":
            write_csv(storage, sys.stdout, ids)
        else:
            with open(args.pareto, "w", newline="") as fh:
                write_csv(storage, fh, ids)
            print(f"wrote {len(ids)} Pareto-front trials to {args.pareto}", file=sys.stderr)
    body = storage.run_meta().run.get("body")
    if args.spec is not None:
        _write_body(storage, args.spec, args.trial)
    if args.gait is not None:
        from spinefarm.storage.export import gait_params, write_gait

        gait = gait_params(storage, args.trial)
        if body:  # the body's constants go to --spec's robot file; the gait file holds the gait alone
            from spinefarm.robot.codesign import BODY_PREFIX

            gait["params"] = {k: v for k, v in gait["params"].items() if not k.startswith(BODY_PREFIX)}
        else:
            _record_spec(storage.run_meta(), gait)
        write_gait(args.gait, gait)
        which = "the best trial" if args.trial is None else f"trial {args.trial}"
        print(f"wrote the parameters of {which} to {args.gait}", file=sys.stderr)
    return 0


def _record_spec(meta: Any, gait: dict[str, Any]) -> None:
    """A robot of a spec file goes into its gait file (`morphology_spec`), so `spinefarm trial --params` alone
    runs it; a built-in's name says enough."""
    from spinefarm.robot.morphology.registry import builtin_names

    if meta.morphology_spec and meta.morphology not in builtin_names():
        gait["morphology_spec"] = meta.morphology_spec


def _write_body(storage: Any, out: str, trial_id: int | None) -> None:
    """The best trial's (or trial_id's) body as a robot file that builds the robot it ran."""
    from pathlib import Path

    import numpy as np

    from spinefarm.protocol.run import RunConfig
    from spinefarm.robot.codesign import BodySearch, body_of_trial, body_spec_text
    from spinefarm.storage.export import gait_params

    meta = storage.run_meta()
    if not meta.run.get("body"):
        raise ConfigError("--spec needs a co-designed run", received=f"run {meta.run_id} searched a fixed body",
                          expected="a run of a spec file with a `search:` block")
    source = gait_params(storage, trial_id)["source"]  # the best complete trial, or trial_id if complete
    record = storage.trial(source["trial_id"])
    config = RunConfig.from_dict(meta.run)
    values, _ = body_of_trial(config, np.asarray(record.params_unit, dtype=float))
    header = (f"the body of trial {record.trial_id} of run {meta.run_id}: distance {record.distance_m:.6g} m, "
              f"speed {record.speed_cm_s:.4g} cm/s, COT {record.cot:.4g} (seed {record.seed})\n"
              + "".join(f"{path} = {v!r}\n" for path, v in values.items()))
    Path(out).parent.mkdir(parents=True, exist_ok=True)
    Path(out).write_text(body_spec_text(BodySearch.from_dict(config.body), values, header))
    print(f"wrote the body of trial {record.trial_id} to {out}", file=sys.stderr)


def _write_parquet(run_file: str, out: str) -> None:
    try:
        import pyarrow  # noqa: F401
    except ImportError as exc:
        raise ConfigError("--parquet needs pyarrow", received="no pyarrow here",
                          expected="pip install 'spinefarm[parquet]'") from exc
    from spinefarm import load_run

    df = load_run(run_file)
    df.to_parquet(out)
    print(f"wrote {len(df)} trials to {out}", file=sys.stderr)
