"""GET /: the dashboard (one static page over the JSON API); /docs and /redoc with assets served locally."""

from __future__ import annotations

from pathlib import Path

from fastapi import APIRouter, FastAPI
from fastapi.openapi.docs import get_redoc_html, get_swagger_ui_html
from fastapi.responses import FileResponse, Response
from fastapi.staticfiles import StaticFiles

STATIC_DIR = Path(__file__).resolve().parent.parent / "static"

router = APIRouter(include_in_schema=False)

# The pages load only what this server serves: a bundled script that reaches for a CDN (Redoc's footer
# logo) is stopped by the browser instead of leaking a request.
CSP = ("default-src 'self'; img-src 'self' data: blob:; style-src 'self' 'unsafe-inline'; "
       "script-src 'self' 'unsafe-inline'; worker-src 'self' blob:; connect-src 'self'; font-src 'self' data:")


def _local_only(resp: Response) -> Response:
    resp.headers["Content-Security-Policy"] = CSP
    return resp


@router.get("/")
def index() -> Response:
    return _local_only(FileResponse(STATIC_DIR / "index.html", media_type="text/html"))


@router.get("/favicon.ico")
def favicon() -> Response:
    return FileResponse(STATIC_DIR / "favicon.svg", media_type="image/svg+xml")


@router.get("/docs")
def swagger() -> Response:
    return _local_only(get_swagger_ui_html(openapi_url="/openapi.json", title="spinefarm API",
                               swagger_js_url="/static/vendor/swagger/swagger-ui-bundle.js",
                               swagger_css_url="/static/vendor/swagger/swagger-ui.css",
                               swagger_favicon_url="/favicon.ico"))


@router.get("/redoc")
def redoc() -> Response:
    return _local_only(get_redoc_html(openapi_url="/openapi.json", title="spinefarm API",
                          redoc_js_url="/static/vendor/redoc.standalone.js",
                          redoc_favicon_url="/favicon.ico", with_google_fonts=False))


def install(app: FastAPI) -> None:
    app.mount("/static", StaticFiles(directory=str(STATIC_DIR)), name="static")
    app.include_router(router)
