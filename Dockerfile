# One image recipe for the Python services (`spinefarm <sub-command>`); EXTRAS picks what a service
# carries: worker (simulators), coordinator,worker (writer + re-simulation of bests), api (no simulator).
# Build stage compiles what has no wheel (pybullet on some platforms); the runtime stage stays slim.
FROM python:3.11-slim AS build
ARG EXTRAS=all
RUN apt-get update \
 && apt-get install -y --no-install-recommends build-essential \
 && rm -rf /var/lib/apt/lists/*
RUN python -m venv /opt/venv
ENV PATH=/opt/venv/bin:$PATH PIP_NO_CACHE_DIR=1
WORKDIR /src
# Only what the package needs: the build context may hold runs and a local venv.
COPY pyproject.toml setup.py README* ./
COPY docs docs
COPY spinefarm spinefarm
COPY protocol protocol
COPY robot robot
COPY worker worker
COPY coordinator coordinator
COPY storage storage
COPY api api
COPY cli cli
RUN pip install --upgrade pip && pip install ".[${EXTRAS}]"

FROM python:3.11-slim
ENV PATH=/opt/venv/bin:$PATH PYTHONUNBUFFERED=1 PYTHONDONTWRITEBYTECODE=1
COPY --from=build /opt/venv /opt/venv
RUN useradd --create-home --uid 1000 spinefarm && mkdir /runs && chown spinefarm /runs
USER spinefarm
WORKDIR /home/spinefarm
VOLUME ["/runs"]
ENTRYPOINT ["spinefarm"]
CMD ["--help"]
