# The two commands of the README: `make demo` (set up + main job) and `make test` (set up + tests).
PY      ?= python3
VENV    ?= .venv
# The one place where the PyTorch build is chosen: 2.13.0 is the CPU wheel on this machine kind;
# an unpinned `torch` would pull a multi-GB CUDA build. On a GPU machine: make TORCH=torch setup
TORCH   ?= torch==2.13.0
BIN      = $(VENV)/bin

.PHONY: setup demo test clean
setup: $(VENV)/.installed

$(VENV)/.installed: pyproject.toml
	$(PY) -m venv $(VENV)
	$(BIN)/pip install -q --upgrade pip
	$(BIN)/pip install -q "$(TORCH)"
	$(BIN)/pip install -q -e ".[dev]"
	touch $@

demo: setup
	$(BIN)/retarget demo

test: setup
	OMP_NUM_THREADS=2 $(BIN)/python -m pytest -q tests

clean:
	rm -rf $(VENV) build *.egg-info
