# The two commands of the README: `make demo` (set up + main job) and `make test` (set up + tests).
PY      ?= python3
VENV    ?= .venv
# The one place where the PyTorch build is chosen: 2.13.0 is the CPU wheel on this machine kind;
# an unpinned `torch` would pull a multi-GB CUDA build. On a GPU machine: make TORCH=torch setup
TORCH   ?= torch==2.13.0
BIN      = $(VENV)/bin

# The Khronos glTF validator (npm) checks the GLB files in the tests; skipped where npm is absent.
GLTF_VALIDATOR = gltf-validator@2.0.0-dev.3.10
VALIDATOR_DIR  = build/gltf-validator

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

$(VALIDATOR_DIR)/.installed:
	@if command -v npm >/dev/null 2>&1; then \
	  npm install --silent --no-audit --no-fund --prefix $(VALIDATOR_DIR) $(GLTF_VALIDATOR) && touch $@ \
	    || echo "could not install $(GLTF_VALIDATOR): its test will be skipped"; \
	else echo "npm not found: the Khronos glTF validator test will be skipped"; fi

test: setup $(VALIDATOR_DIR)/.installed
	OMP_NUM_THREADS=2 GLTF_VALIDATOR_DIR=$(VALIDATOR_DIR) $(BIN)/python -m pytest -q tests

clean:
	rm -rf $(VENV) build *.egg-info
