# Entry points (see README): `make demo` generates motion from text with the shipped model,
# `make data` builds the dataset from the bundled mocap, `make test` runs the whole test suite.
# All create or reuse the venv in .venv; torch is installed first, pinned to the CPU build on disk.
VENV ?= .venv
PY := $(VENV)/bin/python
MOCAP ?= ../shared/data/mocap
BUILD ?= data_build/mocap

$(VENV)/.installed: pyproject.toml
	test -x $(PY) || python3 -m venv $(VENV)
	$(PY) -m pip install -q --disable-pip-version-check torch==2.13.0
	$(PY) -m pip install -q --disable-pip-version-check -e '.[dev]'
	touch $@

.PHONY: install demo data test
install: $(VENV)/.installed

demo: $(VENV)/.installed
	$(VENV)/bin/physmotion generate "a person walks forward" --seconds 6 --num 2 -o out/demo

data: $(VENV)/.installed
	$(VENV)/bin/physmotion data build --source $(MOCAP) --out $(BUILD)
	$(VENV)/bin/physmotion data stats $(BUILD)

test: $(VENV)/.installed
	$(PY) -m pytest -q
