# Two entry points (see README.md):
#   make run   - create .venv if missing, install, run the main job
#   make test  - create .venv if missing, install, run the whole test suite (serial + mpirun -n 2)
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
NP     ?= 2

.PHONY: run test install clean-results

install: $(STAMP)

$(STAMP): pyproject.toml
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[test]'
	touch $(STAMP)

run: $(STAMP)
	$(BIN)/python demos/valve_geometry.py --out results/geometry
	$(BIN)/valve-dolfinx run --out results/normal_valve

test: $(STAMP)
	$(BIN)/python -m pytest
	$(BIN)/mpirun -n $(NP) $(BIN)/python -m pytest -q -m mpi -p no:cacheprovider

clean-results:
	rm -rf results
