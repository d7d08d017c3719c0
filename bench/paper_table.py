"""The paper's table from a script: every shipped gait over N seeded, perturbed episodes, as distributions.

For each gait in examples/gaits/, N episodes (each its own world: ground friction x (1 + U(-0.1, 0.1)) and a
0.5 cm start jitter by default, drawn from (seed, episode) as a robust search draws them), run in Bullet at
the default step, in Bullet at the converged step (0.25 ms) and in MuJoCo. Per spine and engine: median and
interquartile range of speed and COT, beside the paper's figures. Prints one JSON object (last line);
--write-docs puts the table into docs/results.md (between its paper_table markers).

    python bench/paper_table.py [--episodes 16] [--configs bullet,bullet_converged,mujoco] [--workers 2]
    python bench/paper_table.py --episodes 3 --duration 4 --configs bullet      # the reduced form the tests run
    python bench/paper_table.py --gaits efficient/tetraspine --scene flat,ground_half_extent_cm=1000  # a 20 m ground
"""

from __future__ import annotations

import argparse
import json
import re
import sys
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

GAITS = ROOT / "examples" / "gaits"
DOCS = ROOT / "docs" / "results.md"
# the paper (Mirletz et al. 2014, section IV): speed cm/s and COT of its learned gait per spine
PAPER = {"tetraspine": (9.46, 3.2), "tetrahedral-complex": (6.13, 2.13), "octahedral-complex": (4.6, 3.4),
         "ribbed": (5.37, 6.0)}
CONFIGS = {"bullet": {"engine": "bullet"}, "bullet_converged": {"engine": "bullet", "dt_s": 2.5e-4},
           "mujoco": {"engine": "mujoco"}}
CONFIG_NAMES = {"bullet": "Bullet, 1 ms (default)", "bullet_converged": "Bullet, 0.25 ms (converged)",
                "mujoco": "MuJoCo, 1 ms (default)"}
DEFAULT_RANDOMIZE = "friction=0.1,start_jitter_cm=0.5"


def episode(gait: str, config: str, k: int, randomize: str, seed: int, duration_s: float | None,
            scene: str | None = None) -> dict:
    """One episode of one gait in one engine configuration (runs in a pool process)."""
    from spinefarm.cli.sim_commands import load_params_file
    from spinefarm.protocol.robust import RobustSpec, draw_episode, parse_randomize
    from spinefarm.robot.morphology.registry import load_morphology
    from spinefarm.robot.scene import parse_scene
    from spinefarm.worker.trial.robust import episode_world, run_worlds
    from spinefarm.worker.trial.simulation import TrialConfig

    path = GAITS / f"{gait}.json"
    params, controller = load_params_file(path)
    morph = load_morphology(json.loads(path.read_text())["morphology"])
    cfg = TrialConfig(duration_s=duration_s, controller=controller, scene=parse_scene(scene) if scene else {},
                      **CONFIGS[config])
    spec = RobustSpec(episodes=k + 1, randomize=parse_randomize(randomize))
    world = episode_world(morph, cfg, draw_episode(spec, seed, k))
    r = run_worlds([world], params, controller)[0]
    return {"gait": gait, "config": config, "episode": k, "status": r.status.value, "reason": r.reason,
            "speed_cm_s": r.speed_cm_s, "cot": r.cot, "distance_m": r.distance_m, "sim_time_s": r.sim_time_s,
            "wall_time_s": r.wall_time_s, "friction_scale": world.draw.friction_scale}


def summarise(rows: list[dict]) -> dict:
    import numpy as np

    ok = [r for r in rows if r["status"] == "complete"]
    speed = np.array([r["speed_cm_s"] for r in ok])
    cot = np.array([r["cot"] for r in ok])
    if not ok:
        return {"episodes": len(rows), "failed": len(rows)}
    q25, q50, q75 = (float(x) for x in np.percentile(speed, [25, 50, 75]))
    c25, c50, c75 = (float(x) for x in np.percentile(cot, [25, 50, 75]))
    return {"episodes": len(rows), "failed": len(rows) - len(ok), "median_speed_cm_s": q50,
            "iqr_speed_cm_s": q75 - q25, "q25_speed_cm_s": q25, "q75_speed_cm_s": q75,
            "min_speed_cm_s": float(speed.min()), "max_speed_cm_s": float(speed.max()),
            "median_cot": c50, "iqr_cot": c75 - c25}


def table(result: dict, tolerance: float | None = None) -> str:
    """The markdown table of a result (one row per spine and engine configuration); with a tolerance, the
    speed and COT ranges a check accepts (median x (1 -/+ tolerance))."""
    extra = " accepted speed, cm/s | accepted COT |" if tolerance else ""
    lines = ["| spine | paper: speed, COT | engine, step | median speed, cm/s (IQR) | q25 - q75 speed | "
             "median COT (IQR) | failed |" + extra, "|---|---|---|---|---|---|---|" + ("---|---|" if tolerance else "")]
    for gait, s in result["spines"].items():
        for config, c in s["configs"].items():
            head = f"| {gait} | {s['paper_speed_cm_s']} cm/s, {s['paper_cot']} | {CONFIG_NAMES[config]} |"
            if "median_speed_cm_s" not in c:
                lines.append(f"{head} - | - | - | {c['failed']} of {c['episodes']} |")
                continue
            row = (f"{head} **{c['median_speed_cm_s']:.2f}** ({c['iqr_speed_cm_s']:.2f}) | "
                   f"{c['q25_speed_cm_s']:.2f} - {c['q75_speed_cm_s']:.2f} | "
                   f"{c['median_cot']:.2f} ({c['iqr_cot']:.2f}) | {c['failed']} of {c['episodes']} |")
            if tolerance:
                v, cot = c["median_speed_cm_s"], c["median_cot"]
                row += (f" [{v * (1 - tolerance):.3f}, {v * (1 + tolerance):.3f}] |"
                        f" [{cot * (1 - tolerance):.3f}, {cot * (1 + tolerance):.3f}] |")
            lines.append(row)
    return "\n".join(lines)


def write_docs(result: dict, command: str, configs: str, tolerance: float | None) -> None:
    """The table into docs/results.md between markers named by the configs (one block per set of them)."""
    key = configs + ("" if result["duration"] is None else f" {result['duration']:g} s")
    mark_begin, mark_end = f"<!-- paper_table {key}: begin -->", f"<!-- paper_table {key}: end -->"
    text = DOCS.read_text()
    length = "each morphology's" if result["duration"] is None else f"{result['duration']:g} s"
    block = (f"{mark_begin}\n{result['episodes']} episodes per spine and engine ({result['randomize']}, seed "
             f"{result['seed']}, {length} trial length), re-created by\n\n"
             f"    {command}\n\n{table(result, tolerance)}\n{mark_end}")
    if mark_begin in text:
        text = re.sub(re.escape(mark_begin) + ".*?" + re.escape(mark_end), lambda _: block, text, flags=re.S)
    else:
        text = text.rstrip("\n") + "\n\n" + block + "\n"
    DOCS.write_text(text)


def command(result: dict, tolerance: float | None = None) -> str:
    """The command that re-creates a result (and its docs table)."""
    configs = ",".join(next(iter(result["spines"].values()))["configs"])
    parts = ["python bench/paper_table.py", f"--episodes {result['episodes']}", f"--configs {configs}",
             f"--gaits {','.join(result['spines'])}"]
    if result["duration"] is not None:
        parts.append(f"--duration {result['duration']:g}")
    if result["randomize"] != DEFAULT_RANDOMIZE:
        parts.append(f"--randomize {result['randomize']}")
    if result["seed"]:
        parts.append(f"--seed {result['seed']}")
    if result.get("scene"):
        parts.append(f"--scene {result['scene']}")
    if tolerance:
        parts.append(f"--tolerance {tolerance:g}")
    return " ".join([*parts, "--write-docs"])


def main() -> None:
    from spinefarm.cli import checks  # an argparse type: seeds are whole numbers >= 0

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--episodes", type=int, default=16, help="episodes per spine and engine (default 16)")
    ap.add_argument("--configs", default=",".join(CONFIGS), help=f"of {', '.join(CONFIGS)}")
    ap.add_argument("--gaits", default=",".join(PAPER),
                    help="shipped gaits (examples/gaits/NAME.json; a subfolder's as efficient/NAME)")
    ap.add_argument("--randomize", default=DEFAULT_RANDOMIZE, help="each episode's draw, as search --randomize")
    ap.add_argument("--seed", type=checks.seed, default=0, help="the episodes' seed (episode k: from (seed, k))")
    ap.add_argument("--duration", type=float, default=None, help="trial length (default: each morphology's)")
    ap.add_argument("--scene", default=None, help="what the gaits run on, as trial --scene (default: NTRT's ground)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--write-docs", action="store_true", help="put the table into docs/results.md")
    ap.add_argument("--tolerance", type=float, default=None,
                    help="with --write-docs: also write the ranges a check accepts, median x (1 -/+ this)")
    ap.add_argument("--from-json", metavar="FILE", help="write the docs table of an earlier run's JSON (no simulation)")
    args = ap.parse_args()
    if args.from_json:
        result = json.loads(Path(args.from_json).read_text().strip().splitlines()[-1])
        configs = ",".join(next(iter(result["spines"].values()))["configs"])
        write_docs(result, command(result, args.tolerance), configs, args.tolerance)
        return
    configs, gaits = args.configs.split(","), args.gaits.split(",")
    bad = [c for c in configs if c not in CONFIGS] + [g for g in gaits if not (GAITS / f"{g}.json").is_file()
                                                      or Path(g).name not in PAPER]
    if bad or args.episodes < 1:
        sys.exit(f"paper_table: unknown config or gait {bad} or episodes {args.episodes}; expected configs of "
                 f"{list(CONFIGS)}, gaits of examples/gaits/, episodes >= 1")
    if args.scene:
        from spinefarm.protocol.errors import ConfigError
        from spinefarm.robot.scene import parse_scene

        try:
            parse_scene(args.scene)  # a bad scene is told here, once, not by every episode
        except ConfigError as e:
            sys.exit(f"paper_table: --scene: {e}")
    t0 = time.perf_counter()
    jobs = [(g, c, k) for g in gaits for c in configs for k in range(args.episodes)]
    with ProcessPoolExecutor(args.workers) as pool:
        futures = [pool.submit(episode, g, c, k, args.randomize, args.seed, args.duration, args.scene)
                   for g, c, k in jobs]
        for done, fut in enumerate(as_completed(futures), 1):  # progress on stderr, one line per episode
            r = fut.result()
            print(f"{done}/{len(jobs)} {r['gait']} {r['config']} episode {r['episode']}: {r['speed_cm_s']:.3f} cm/s "
                  f"({r['status']})", file=sys.stderr, flush=True)
        rows = [f.result() for f in futures]
    spines = {}
    for g in gaits:
        per = {c: summarise([r for r in rows if r["gait"] == g and r["config"] == c]) for c in configs}
        head = per[configs[0]]
        paper = PAPER[Path(g).name]  # a gait in a subfolder (robust/, efficient/) is still its spine's
        spines[g] = {"paper_speed_cm_s": paper[0], "paper_cot": paper[1], "headline_config": configs[0],
                     **{k: head.get(k) for k in ("median_speed_cm_s", "iqr_speed_cm_s", "median_cot")},
                     "configs": per}
    result = {"episodes": args.episodes, "randomize": args.randomize, "seed": args.seed, "duration": args.duration,
              "scene": args.scene, "spines": spines, "wall_time_s": time.perf_counter() - t0, "rows": rows}
    if args.write_docs:
        write_docs(result, command(result, args.tolerance), args.configs, args.tolerance)
    print(json.dumps(result))


if __name__ == "__main__":
    main()
