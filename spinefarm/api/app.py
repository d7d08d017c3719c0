"""create_app(): the read-only HTTP status API over run files."""

from __future__ import annotations

from collections.abc import AsyncIterator, Sequence
from contextlib import asynccontextmanager
from pathlib import Path

from fastapi import Depends, FastAPI

from spinefarm.api import errors
from spinefarm.api.pictures import PictureCache
from spinefarm.api.registry import RunRegistry
from spinefarm.api.routers import dashboard, episodes, files, notes, runs, trials
from spinefarm.api.schemas import ErrorResponse
from spinefarm.protocol.errors import ConfigError


def create_app(run_files: Sequence[str | Path] = (), runs_dir: str | Path | None = None,
               picture_cache_dir: str | Path | None = None) -> FastAPI:
    """Serve the given run files and/or every *.h5 in `runs_dir`. Run files are only ever read (a reader's notes
    go to a file beside each, api.notes); gait
    pictures are drawn on demand into `picture_cache_dir` (default: a folder in the temp dir)."""
    if not run_files and runs_dir is None:
        raise ConfigError("the API needs run files or a runs directory", expected="run_files or runs_dir")

    @asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        app.state.registry = RunRegistry([Path(f) for f in run_files],
                                         Path(runs_dir) if runs_dir is not None else None)
        app.state.pictures = PictureCache(Path(picture_cache_dir) if picture_cache_dir is not None else None)
        try:
            yield
        finally:
            app.state.registry.close()

    responses = {404: {"model": ErrorResponse}, 409: {"model": ErrorResponse}, 422: {"model": ErrorResponse}}
    app = FastAPI(title="spinefarm",
                  summary="Status and results of gait searches (run files read-only; notes kept beside them)",
                  lifespan=lifespan, responses=responses, docs_url=None, redoc_url=None)
    errors.install(app)
    json_api = [Depends(errors.known_query)]  # the JSON API refuses unknown query parameters; pages do not
    for router in (runs.router, runs.files_router, trials.router, episodes.router, files.router, notes.router):
        app.include_router(router, dependencies=json_api)
    dashboard.install(app)

    @app.get("/health", tags=["health"])
    def health() -> dict[str, str]:
        return {"status": "ok"}

    return app
