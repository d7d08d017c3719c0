# One image recipe for the Python services (`spinefarm <sub-command>`); EXTRAS picks what a service
# carries: worker (simulators), coordinator,worker (writer + re-simulation of bests), api (no simulator).
# BASE: any Debian-like image with Python 3.11 (python:3.11-slim by default; deploy/compose.offline.yml
# builds on a Debian bookworm base made locally). OFFLINE=1 fetches nothing: every package comes from
# the wheelhouse WHEELS, a folder of the build context holding the wheels of all the package needs
# (made with `pip wheel` on a machine that reaches the index; see docs/deploy.md).
# Dependencies and code are separate layers: a change of code rebuilds only the last ones.
ARG BASE=python:3.11-slim

# The dependencies of EXTRAS in /opt/venv: they change only with pyproject.toml and the wheelhouse.
# build-essential compiles what has no wheel (pybullet on some platforms); the runtime image stays slim.
FROM ${BASE} AS deps
ARG OFFLINE=
RUN if [ -z "$OFFLINE" ]; then apt-get update \
 && apt-get install -y --no-install-recommends build-essential \
 && rm -rf /var/lib/apt/lists/*; fi \
 && python3 -m venv /opt/venv
ARG WHEELS=deploy/wheels
COPY ${WHEELS} /wheels
COPY pyproject.toml deploy/requirements.py /src/
ARG EXTRAS=all
ENV PATH=/opt/venv/bin:$PATH PIP_NO_CACHE_DIR=1 PIP_DISABLE_PIP_VERSION_CHECK=1
RUN pip install -q ${OFFLINE:+--no-index} --find-links /wheels --upgrade pip \
 && python3 /src/requirements.py /src/pyproject.toml "$EXTRAS" > /src/requirements.txt \
 && pip install -q ${OFFLINE:+--no-index} --find-links /wheels -r /src/requirements.txt

# The package itself, into a folder of its own: only what it is built from.
FROM deps AS code
COPY pyproject.toml setup.py README.md /src/
COPY docs /src/docs
COPY spinefarm /src/spinefarm
RUN pip install -q --no-deps ${OFFLINE:+--no-index} --find-links /wheels --target /pkg /src \
 && mv /pkg/bin /pkg-bin

FROM ${BASE}
RUN useradd --create-home --uid 1000 spinefarm && mkdir /runs && chown spinefarm /runs
ENV PATH=/opt/venv/bin:$PATH PYTHONUNBUFFERED=1 PYTHONDONTWRITEBYTECODE=1
COPY --from=deps /opt/venv /opt/venv
COPY --from=code /pkg /opt/venv/lib/python3.11/site-packages/
COPY --from=code /pkg-bin /opt/venv/bin/
USER spinefarm
WORKDIR /home/spinefarm
VOLUME ["/runs"]
ENTRYPOINT ["spinefarm"]
CMD ["--help"]
