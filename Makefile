# Two entry points (see README): `make demo` runs the main job, `make test` the whole test suite.
# Both create or reuse the venv in .venv; torch is installed first, pinned to the CPU build on disk.
VENV ?= .venv
PY := $(VENV)/bin/python
MOCAP ?= ../shared/data/mocap
BUILD ?= data_build/mocap

$(VENV)/.installed: pyproject.toml
	test -x $(PY) || python3 -m venv $(VENV)
	$(PY) -m pip install -q --disable-pip-version-check torch==2.13.0
	$(PY) -m pip install -q --disable-pip-version-check -e '.[dev]'
	touch $@

.PHONY: install demo test
install: $(VENV)/.installed

demo: $(VENV)/.installed
	$(VENV)/bin/physmotion data build --source $(MOCAP) --out $(BUILD)
	$(VENV)/bin/physmotion data stats $(BUILD)

test: $(VENV)/.installed
	$(PY) -m pytest -q
