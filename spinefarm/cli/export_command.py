"""`spinefarm export`: a run file as CSV or Parquet, its best trials, its Pareto front or a gait file."""

from __future__ import annotations

import argparse
import sys

from spinefarm.cli import checks
from spinefarm.protocol.errors import ConfigError


def cmd_export(args: argparse.Namespace) -> int:
    from spinefarm.storage.export import best_table, write_csv
    from spinefarm.storage.hdf5 import Hdf5Storage

    if all(v is None for v in (args.csv, args.best, args.pareto, args.parquet, args.gait)):
        raise ConfigError("nothing to export", expected="--csv [OUT.csv], --parquet OUT.parquet, --best K, "
                          "--pareto [OUT.csv] and/or --gait OUT.json")
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
    if args.gait is not None:
        from spinefarm.storage.export import gait_params, write_gait

        write_gait(args.gait, gait_params(storage, args.trial))
        which = "the best trial" if args.trial is None else f"trial {args.trial}"
        print(f"wrote the parameters of {which} to {args.gait}", file=sys.stderr)
    return 0


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
