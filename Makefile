# Entry points (see README): `make demo` generates motion from text with the shipped model,
# `make data` builds the datasets from the bundled mocap (and with HDM05), `make test` runs the whole test suite
# (both tiers, in 2 pytest-xdist workers), `make test-fast` the fast tier alone (what plain `pytest` runs).
# All create or reuse the venv in .venv; torch is installed first, pinned to the CPU build on disk.
VENV ?= .venv
PY := $(VENV)/bin/python
MOCAP ?= ../shared/data/mocap
HDM05 ?= ../shared/data/hdm05
BUILD ?= data_build/mocap
BUILD_ALL ?= data_build/all

$(VENV)/.installed: pyproject.toml
	test -x $(PY) || { echo "creating the virtual environment in $(VENV)"; python3 -m venv $(VENV); }
	@echo "installing torch 2.13.0 (CPU build; the largest download, a minute or more)"
	$(PY) -m pip install --progress-bar on --disable-pip-version-check torch==2.13.0
	@echo "installing physmotion and its dependencies (editable, with [dev])"
	$(PY) -m pip install --progress-bar on --disable-pip-version-check -e '.[dev]'
	touch $@
	@echo "installed: run $(VENV)/bin/physmotion --help"

.PHONY: install demo data test test-fast browser blender gltf-validator render-png
install: $(VENV)/.installed

demo: $(VENV)/.installed
	$(VENV)/bin/physmotion generate "a person walks forward" --seconds 6 --num 2 -o out/demo --overwrite

# $(BUILD): the mocap alone, short clips skipped, as the shipped models and results/ were made;
# $(BUILD_ALL): mocap and HDM05 in one dataset, short clips held to 2 s (docs/cli.md, "data build").
data: $(VENV)/.installed
	$(VENV)/bin/physmotion data build --source $(MOCAP) --out $(BUILD) --no-pad-short --overwrite
	$(VENV)/bin/physmotion data stats $(BUILD)
	$(VENV)/bin/physmotion data build --source $(MOCAP) --source $(HDM05) --out $(BUILD_ALL) --overwrite
	$(VENV)/bin/physmotion data stats $(BUILD_ALL)

# tests/test_view.py opens the viewer page in headless Chromium: install it where it is missing.
browser:
	command -v chromium >/dev/null || (apt-get update -qq && apt-get install -y -qq chromium)

# tests/test_blender.py imports our exports in headless Blender (Debian's blender, 3.4.1 on bookworm;
# about a minute to install): install it where it is missing.
blender:
	command -v blender >/dev/null && python3 -c 'import numpy' 2>/dev/null || (apt-get update -qq && apt-get install -y -qq blender python3-numpy)

# tests/io/test_gltf.py validates the .glb files `export` writes with the Khronos glTF validator (npm
# gltf-validator, Apache-2.0), run by node: install it into .cache/node (ignored by git) where it is missing.
GLTF_VALIDATOR := .cache/node/node_modules/gltf-validator
gltf-validator:
	command -v node >/dev/null || (apt-get update -qq && apt-get install -y -qq nodejs npm)
	test -f $(GLTF_VALIDATOR)/package.json || npm install --prefix .cache/node --no-audit --no-fund gltf-validator@2.0.0-dev.3.10

# Both tiers (tests/README.md): the fast one and the `slow` one, in 2 workers that build each shared fixture once.
test: $(VENV)/.installed browser blender gltf-validator
	$(PY) -m pytest -q -n 2 -m "slow or not slow" --durations=20

# The fast tier alone, as plain `pytest` runs it (at most 3 min on 2 cores); needs no browser.
test-fast: $(VENV)/.installed
	$(PY) -m pytest -q

# docs/render.png (README): a captured walk beside its physics projection, frame 100 of `physmotion render`.
RENDER_CLIP ?= $(MOCAP)/bandai/Bandai-Namco-Research-Motiondataset-2/data/dataset-2_walk_normal_001.bvh
render-png: $(VENV)/.installed
	tmp=$$(mktemp -d) && \
	$(VENV)/bin/physmotion import $(RENDER_CLIP) -o $$tmp/captured.npz --rig bandai --fps 30 && \
	$(VENV)/bin/physmotion project $$tmp/captured.npz -o $$tmp/projected.npz && \
	$(VENV)/bin/physmotion render $$tmp/captured.npz $$tmp/projected.npz --frame 100 --size 400 -o docs/render.png && \
	rm -rf $$tmp
