"""GET /: the dashboard (one static page over the JSON API); /docs and /redoc with assets served locally."""

from __future__ import annotations

from functools import lru_cache
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


# Redoc's sidebar footer always asks a CDN for its logo; the served copy points it at our own icon instead
# (the vendored file stays as published).
REDOC_CDN_LOGO = "https://cdn.redoc.ly/redoc/logo-mini.svg"


@lru_cache(maxsize=1)
def _redoc_js() -> bytes:
    text = (STATIC_DIR / "vendor" / "redoc.standalone.js").read_text(encoding="utf-8")
    return text.replace(REDOC_CDN_LOGO, "/favicon.ico").encode("utf-8")


@router.get("/redoc.js")
def redoc_js() -> Response:
    return Response(_redoc_js(), media_type="text/javascript", headers={"Cache-Control": "max-age=3600"})


@router.get("/redoc")
def redoc() -> Response:
    return _local_only(get_redoc_html(openapi_url="/openapi.json", title="spinefarm API",
                          redoc_js_url="/redoc.js",
                          redoc_favicon_url="/favicon.ico", with_google_fonts=False))


def install(app: FastAPI) -> None:
    app.mount("/static", StaticFiles(directory=str(STATIC_DIR)), name="static")
    app.include_router(router)
