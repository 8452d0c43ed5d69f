# Two commands do everything on a fresh machine: `make demo` and `make test`.
# Both create .venv with the pinned dependencies of requirements*.txt on first use.

PYTHON ?= python3
VENV   ?= .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed

.PHONY: demo test lint typecheck bench venv clean clean-cache lock foxglove-client docs

venv: $(STAMP)

$(STAMP): requirements.txt requirements-dev.txt constraints.txt setup.py
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --disable-pip-version-check -r requirements.txt \
		-r requirements-dev.txt -c constraints.txt
	$(PY) -m pip install --quiet --disable-pip-version-check --no-deps --no-build-isolation -e .
	$(PY) -m biped_opt.codegen.kernel
	touch $(STAMP)

demo: $(STAMP)
	$(VENV)/bin/biped-opt demo

# Two test workers (pytest-xdist; `make test TEST_WORKERS=0` runs in one process): a test marked
# alone runs while no other does, and tests sharing a module's fixture go to one worker.
TEST_WORKERS ?= 2

test: $(STAMP) lint typecheck foxglove-client docs
	$(PY) -m pytest -n $(TEST_WORKERS) --dist loadgroup

# The manual (docs/, Sphinx with MyST): tutorials, how-to guides, the specifications and the API
# reference from the docstrings, to docs/_build/html; a warning is an error. Its code examples
# run in the test suite (tests/test_docs_examples.py).
docs: $(STAMP)
	rm -rf docs/reference/generated
	$(PY) -m sphinx -W --keep-going -q -b html docs docs/_build/html
	@echo "the manual: docs/_build/html/index.html"

# The live view's test client (tests/nodes/test_foxglove.py): Foxglove's own WebSocket protocol
# client and ROS 2 decoders under Node.js, at the versions package-lock.json pins. Without npm
# (or when it cannot install) the test skips and says why; `make test` goes on.
CLIENT_DIR   := tests/nodes/foxglove_client
CLIENT_STAMP := $(CLIENT_DIR)/node_modules/.installed

foxglove-client: $(CLIENT_STAMP)

$(CLIENT_STAMP): $(CLIENT_DIR)/package.json $(CLIENT_DIR)/package-lock.json
	@if command -v npm >/dev/null 2>&1; then \
		npm ci --prefix $(CLIENT_DIR) --ignore-scripts --no-audit --no-fund --loglevel=error \
			&& touch $@ \
			|| echo "npm ci failed: the live Foxglove view's client test will skip"; \
	else \
		echo "npm not found: the live Foxglove view's client test will skip"; \
	fi

lint: $(STAMP)
	$(VENV)/bin/ruff check biped_opt tests bench launch

# The numerical core, as setup.cfg's [mypy] section lists it.
typecheck: $(STAMP)
	$(PY) -m mypy

bench: $(STAMP)
	$(VENV)/bin/biped-opt bench

# Numba's on-disk cache is keyed by each file's own source, not by the kernels it inlines from
# other files: after editing biped_opt/model or biped_opt/hybrid, drop it (a fresh clone has none).
clean-cache:
	find biped_opt -name '*.nbi' -o -name '*.nbc' | xargs rm -f

# Regenerate constraints.txt after changing a pin in requirements*.txt.
lock: $(STAMP)
	{ sed -n '1,2p' constraints.txt; $(PY) -m pip freeze --exclude-editable | grep -v '^biped'; } \
		> constraints.txt.new && mv constraints.txt.new constraints.txt

clean: clean-cache
	rm -rf $(VENV) build *.egg-info .mypy_cache docs/_build docs/reference/generated
