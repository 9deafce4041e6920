# Two commands set everything up on a fresh machine with Python 3.11 and make:
#   make demo   create .venv, install, run the main job
#   make test   create .venv, install, lint (ruff), type-check (mypy), run the test suite
PYTHON ?= python3
VENV ?= .venv
TORCH_SPEC ?= torch==2.13.0
# empty: PyPI (on Linux its torch wheels are the CUDA build); https://download.pytorch.org/whl/cpu for the CPU build
TORCH_INDEX ?=
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: demo test install clean bench

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)

$(STAMP): $(BIN)/python pyproject.toml
	$(BIN)/pip install --upgrade pip
	$(BIN)/pip install "$(TORCH_SPEC)" $(if $(TORCH_INDEX),--index-url $(TORCH_INDEX))
	$(BIN)/pip install -e ".[test,ray,marl]"
	touch $(STAMP)

install: $(STAMP)

demo: $(STAMP)
	$(BIN)/python examples/demo.py

test: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/mypy
	$(BIN)/python -m pytest -n 2 tests

bench: $(STAMP)
	$(BIN)/safe-mapf bench-env SafeCentralObstacle-v0

clean:
	rm -rf $(VENV) build *.egg-info
