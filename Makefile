# One command sets up and renders the Cornell box; one sets up and runs the tests.
# torch is installed first, the CPU build from PyTorch's CPU-only index (the registry's Linux wheel
# is the CUDA build); where that index cannot be reached (only the registry is), from the registry.
PY ?= python3
VENV ?= .venv
BIN := $(VENV)/bin
SCENE ?= scenes/cornell/cornell.obj
OUT ?= out/cornell.exr
TORCH_INDEX ?= https://download.pytorch.org/whl/cpu

.PHONY: setup demo test bench clean

$(BIN)/python:
	$(PY) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip

$(VENV)/.installed: $(BIN)/python pyproject.toml
	$(BIN)/pip install --quiet --retries 1 --timeout 30 --index-url $(TORCH_INDEX) torch==2.13.0 || \
		$(BIN)/pip install --quiet torch==2.13.0
	$(BIN)/pip install --quiet -e ".[test,bench,learn,mitsuba,denoise,dask]"
	touch $@

setup: $(VENV)/.installed

demo: setup
	mkdir -p $(dir $(OUT))
	$(BIN)/python -m tracer $(SCENE) -o $(OUT)

test: setup
	$(BIN)/python -m pytest -q

bench: setup
	$(BIN)/python -m bench.throughput

clean:
	rm -rf $(VENV) out
