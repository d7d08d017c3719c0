"""spinefarm from Python: `spinefarm.load_run(path)` gives a run file as a pandas DataFrame.

    import spinefarm
    df = spinefarm.load_run("runs/tetra.h5")
    df[df.status == "complete"].sort_values("objective").tail()
    df.attrs["units"]["speed_cm_s"]   # 'cm/s'
    eps = spinefarm.load_run("runs/robust.h5", episodes=True)   # a robust run: one row per episode
"""

from __future__ import annotations

from importlib.metadata import PackageNotFoundError, version
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    import pandas as pd

try:
    __version__ = version("spinefarm")
except PackageNotFoundError:  # a source tree that was never installed
    __version__ = "0+unknown"

__all__ = ["__version__", "load_episodes", "load_run"]


def load_run(path: str | Path, episodes: bool = False) -> pd.DataFrame:
    """One row per trial (index trial_id), every stored column, parameters as named columns of physical values.
    With episodes=True: the run's episodes instead (load_episodes).

    `df.attrs["units"]` maps column -> unit; `df.attrs["run"]` holds the run's metadata (run id, robot,
    controller, objective, trial config, sampler, parameter bounds). Works on a live run file too.
    """
    if episodes:
        return load_episodes(path)
    import numpy as np
    import pandas as pd

    from spinefarm.storage.hdf5_reader import read_run
    from spinefarm.storage.probe import probe
    from spinefarm.storage.schema import COLUMNS, VECTOR_COLUMNS

    if Path(path).is_file():
        probe(path)  # a damaged file: a StorageError within the probe's deadline, never a hang
    meta, cols = read_run(path)
    data: dict[str, Any] = {}
    units: dict[str, str] = {}
    for c in COLUMNS:
        if c.name in VECTOR_COLUMNS or c.name == "trial_id":
            continue
        v = np.asarray(cols[c.name])
        data[c.name] = [x.decode("utf-8", "replace") for x in v.tolist()] if v.dtype.kind == "S" else v
        units[c.name] = c.unit
    units["objective"] = meta.objective
    params = np.asarray(cols["params"], dtype=float).reshape(len(cols["trial_id"]), meta.n_params)
    for j, (name, unit) in enumerate(zip(meta.param_names, meta.param_units, strict=True)):
        key = name if name not in data else f"param_{name}"
        data[key] = params[:, j]
        units[key] = unit
    df = pd.DataFrame(data, index=pd.Index(np.asarray(cols["trial_id"]), name="trial_id"))
    df["finished_at"] = pd.to_datetime(df["finished_at_unix_s"], unit="s", utc=True)
    df.attrs["units"] = units
    df.attrs["run"] = {"run_id": meta.run_id, "morphology": meta.morphology, "controller": meta.controller,
                       "objective": meta.objective, "seed": meta.seed, "trials_budget": meta.trials_budget,
                       "trial_config": meta.trial_config, "sampler": meta.sampler,
                       "param_names": list(meta.param_names), "param_units": list(meta.param_units),
                       "param_lows": list(meta.param_lows), "param_highs": list(meta.param_highs),
                       "software_version": meta.software_version, "file": str(path)}
    return df


def load_episodes(path: str | Path) -> pd.DataFrame:
    """The episodes of a robust run (`search --episodes K`): one row per episode, index (trial_id, episode),
    each episode's scores and draw (friction_scale, mass_scale, start_jitter_cm, rough_seed). Empty for a
    plain run. `df.groupby(level="trial_id").speed_cm_s.describe()` gives each trial's spread."""
    import numpy as np
    import pandas as pd

    from spinefarm.storage.episodes import EPISODE_COLUMNS
    from spinefarm.storage.hdf5_reader import read_episodes

    cols = read_episodes(path)
    data = {c.name: ([x.decode("utf-8", "replace") for x in cols[c.name].tolist()] if c.dtype[0] == "S"
                     else np.asarray(cols[c.name])) for c in EPISODE_COLUMNS[2:]}
    index = pd.MultiIndex.from_arrays([np.asarray(cols["trial_id"]), np.asarray(cols["episode"])],
                                      names=["trial_id", "episode"])
    df = pd.DataFrame(data, index=index).sort_index()
    df.attrs["units"] = {c.name: c.unit for c in EPISODE_COLUMNS}
    return df
