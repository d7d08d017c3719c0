"""GET /runs/{run_id}/notes; PUT /runs/{run_id}/notes and /runs/{run_id}/trials/{trial_id}/notes: a reader's
notes, kept beside the run file (api.notes), never in it."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any

from fastapi import APIRouter, Depends
from fastapi import Path as PathParam
from pydantic import BaseModel, Field

from spinefarm.api import notes
from spinefarm.api.deps import run_path
from spinefarm.api.errors import NotFound
from spinefarm.storage.hdf5_reader import Hdf5Reader

router = APIRouter(prefix="/runs/{run_id}", tags=["notes"])


class Notes(BaseModel):
    run: str = Field(description="the note on the run ('' when none)")
    trials: dict[str, str] = Field(description="notes on trials, by trial id")


class NoteText(BaseModel):
    text: str = Field(max_length=notes.MAX_NOTE_CHARS, description="the note ('' removes it)")


@router.get("/notes", response_model=Notes, summary="The notes on the run and its trials (beside the run file)")
def get_notes(path: Annotated[Path, Depends(run_path)]) -> dict[str, Any]:
    return notes.read_notes(path)


@router.put("/notes", response_model=Notes, summary="Set the note on the run ('' removes it)")
def put_run_note(path: Annotated[Path, Depends(run_path)], body: NoteText) -> dict[str, Any]:
    return notes.write_note(path, None, body.text)


@router.put("/trials/{trial_id}/notes", response_model=Notes, summary="Set the note on a trial ('' removes it)")
def put_trial_note(path: Annotated[Path, Depends(run_path)], body: NoteText,
                   trial_id: Annotated[int, PathParam(ge=0, le=2**62)]) -> dict[str, Any]:
    reader = Hdf5Reader(path)
    try:
        n = reader.n_trials()
    finally:
        reader.close()
    if trial_id >= n:
        raise NotFound("no such trial", received=trial_id, expected=f"a trial id below {n}")
    return notes.write_note(path, trial_id, body.text)
