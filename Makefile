# The two commands: `make run` (set up, then a short local search) and `make test` (set up, then the tests).
PYTHON ?= python3
VENV   ?= .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed

.PHONY: install run test test-all test-deploy lint bench clean mutation wheel docs-check

# exact versions and hashes from requirements.lock (docs/reproducibility.md says how to refresh it), then the
# package itself without resolving anything again
$(STAMP): pyproject.toml requirements.lock
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --upgrade pip
	$(PY) -m pip install -q --require-hashes --no-deps -r requirements.lock
	$(PY) -m pip install -q --no-deps -e .
	touch $(STAMP)

install: $(STAMP)

run: $(STAMP)
	$(VENV)/bin/spinefarm search tetrahedral-complex --trials 100 --workers 2 --duration 5 --out runs/tetrahedral-complex-demo.h5 --overwrite

test: $(STAMP)
	sh .ci/ensure-chromium
	sh .ci/ensure-netns-tools
	sh .ci/ensure-qemu-user
	sh .ci/ensure-system-tools
	$(PY) -m ruff check .
	$(PY) -m pytest -q -ra --durations=25 -n 2 --dist loadfile

test-all: $(STAMP)
	sh .ci/ensure-chromium
	sh .ci/ensure-netns-tools
	sh .ci/ensure-qemu-user
	sh .ci/ensure-system-tools
	$(PY) -m pytest -q -ra -m ''

# The compose and SLURM deployments end to end (root only: apt, dockerd, munge, SLURM); docs/deploy.md.
test-deploy: $(STAMP)
	$(PY) -m tests.deploy.main $(DEPLOY_ARGS)

# mutmut over the modules that decide, each against its own few test files (tests/mutation/targets.py); long
# (hours on two cores), so not in `make test`. MUTATION_ARGS: --modules NAME,... (a re-run tests only survivors).
mutation: $(STAMP)
	$(PY) -m pip install -q --require-hashes --no-deps -r tests/mutation/requirements.txt
	$(PY) -m tests.mutation.main $(MUTATION_ARGS)

# the wheel a machine without a clone installs: pip install 'dist/spinefarm-<version>-py3-none-any.whl[all]'
wheel:
	$(PYTHON) -m pip wheel --no-deps -q -w dist .

# the cheap commands the docs quote, run again and compared with the docs' figures (tests/docs_check.py)
docs-check: $(STAMP)
	$(PY) -m tests.docs_check

bench: $(STAMP)
	$(PY) bench/trial_speed.py

clean:
	rm -rf $(VENV) build dist *.egg-info .pytest_cache .ruff_cache
