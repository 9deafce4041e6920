# Two commands set everything up on a fresh machine with Python 3.11 and make:
#   make demo   create .venv, install, run the main job
#   make test   create .venv, install, lint (ruff), type-check (mypy), run the test suite, build the docs
#   make docs   build the documentation site into site/ (mkdocs build --strict: warnings are errors)
PYTHON ?= python3
VENV ?= .venv
TORCH_SPEC ?= torch==2.13.0
# empty: PyPI (on Linux its torch wheels are the CUDA build); https://download.pytorch.org/whl/cpu for the CPU build
TORCH_INDEX ?=
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: demo test install clean bench docs

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)

$(STAMP): $(BIN)/python pyproject.toml
	$(BIN)/pip install --upgrade pip
	$(BIN)/pip install "$(TORCH_SPEC)" $(if $(TORCH_INDEX),--index-url $(TORCH_INDEX))
	$(BIN)/pip install -e ".[test,ray,marl,docs,fast]"
	touch $(STAMP)

install: $(STAMP)

demo: $(STAMP)
	$(BIN)/python examples/demo.py

test: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/mypy
	$(BIN)/python -m pytest -n 2 tests
	$(MAKE) docs

docs: $(STAMP)
	NO_MKDOCS_2_WARNING=1 $(BIN)/mkdocs build --strict

bench: $(STAMP)
	$(BIN)/safe-mapf bench-env SafeCentralObstacle-v0

clean:
	rm -rf $(VENV) build site *.egg-info
