"""Notes a reader keeps on a run and its trials, in a sidecar file beside the run file (RUN.h5.notes.json),
never in the run file itself: a run file stays what its search wrote (its hash, its snapshot, a resume).

The sidecar is {"format": FORMAT, "run": text, "trials": {"<trial id>": text}}; an empty text removes a note.
A sidecar that cannot be read as one is left as it is (a write would lose what it holds): reads and writes say
so. Written to a temporary file and renamed over it, so a reader never sees half a file.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

from spinefarm.protocol.errors import StorageError

FORMAT = "spinefarm-notes/1"
SUFFIX = ".notes.json"
MAX_NOTE_CHARS = 20_000


def notes_path(run_file: Path) -> Path:
    return run_file.with_name(run_file.name + SUFFIX)


def read_notes(run_file: Path) -> dict[str, Any]:
    """{"run": text, "trials": {id: text}} ({} of both when there is no sidecar)."""
    path = notes_path(run_file)
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        return {"run": "", "trials": {}}
    except (OSError, UnicodeDecodeError, ValueError) as exc:
        raise StorageError(f"the notes file cannot be read ({type(exc).__name__}); it is left as it is",
                           received=str(path), expected=f"a {FORMAT} JSON file, or none") from exc
    ok = (isinstance(data, dict) and data.get("format") == FORMAT and isinstance(data.get("run", ""), str)
          and isinstance(data.get("trials", {}), dict) and all(isinstance(v, str) for v in data["trials"].values()))
    if not ok:
        raise StorageError("the notes file is not a spinefarm notes file; it is left as it is", received=str(path),
                           expected=f'{{"format": "{FORMAT}", "run": text, "trials": {{id: text}}}}')
    return {"run": data.get("run", ""), "trials": dict(data.get("trials", {}))}


def write_note(run_file: Path, trial_id: int | None, text: str) -> dict[str, Any]:
    """Set the run's note (trial_id None) or a trial's; returns every note after the change."""
    notes = read_notes(run_file)  # a damaged sidecar is refused here, before anything is written
    if trial_id is None:
        notes["run"] = text
    elif text:
        notes["trials"][str(trial_id)] = text
    else:
        notes["trials"].pop(str(trial_id), None)
    path = notes_path(run_file)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        tmp.write_text(json.dumps({"format": FORMAT, **notes}, indent=1, ensure_ascii=False), encoding="utf-8")
        tmp.replace(path)
    except OSError as exc:
        tmp.unlink(missing_ok=True)
        raise StorageError(f"the note cannot be stored ({exc.strerror or exc})", received=str(path),
                           expected="a writable folder beside the run file") from exc
    return notes
