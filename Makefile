# The README's two commands: `make demo` and `make test`. Both install on first use.
PYTHON ?= python3
VENV ?= .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

.PHONY: install demo test test-person bench clean clean-demo

# The stamp makes a second run instant; editing pyproject.toml reinstalls.
$(STAMP): pyproject.toml
	test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[dev]'
	touch $(STAMP)

install: $(STAMP)

demo: install
	$(VENV)/bin/hemg-drake demo

# Two workers: the suite is dominated by independent Drake simulations.
test: install
	$(PY) -m pytest -n 2 --dist loadfile -m "not person"

# The person tests (marked person): the real teleop page driven by key events through whole
# takes, then learn and reproduce; tens of minutes, as the page runs below real time.
test-person: install
	$(PY) -m pytest -m person -q -s -p no:cacheprovider tests/teleop

# The benchmarks' own data and baselines (the bench extra) install on first use.
bench: install
	$(PY) -m pip install --quiet -e '.[dev,bench]'
	for f in benchmarks/bench_*.py; do echo "== $$f"; $(PY) $$f || exit 1; done

# Caches and build outputs only. runs/ is left alone: the README has users keep their own
# demonstrations and models there (runs/pin/ ...), and a deleted demonstration is not
# rebuilt by anything.
clean:
	rm -rf .pytest_cache build dist *.egg-info
	find . -path ./$(VENV) -prune -o -name __pycache__ -type d -prune -exec rm -rf {} +

# What `make demo` writes, and nothing else: runs/cotter_pin/, runs/drawing/ and
# runs/metrics.json (hemg_drake.pipeline.run_demo's out_dir "runs", one folder per task;
# keep this list in step with it). The next `make demo` would overwrite them anyway, so
# removing them loses nothing a user made; their own folders under runs/ stay.
DEMO_OUTPUTS := runs/cotter_pin runs/drawing runs/metrics.json
clean-demo:
	rm -rf $(DEMO_OUTPUTS)
