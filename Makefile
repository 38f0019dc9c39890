# paretocal: one command for the demo, one for the tests. Each creates .venv when missing.
# `make docs` builds the documentation site into site/ (open site/index.html).
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
DATA   ?= $(or $(PARETOCAL_DATA),../shared/data)
RUN    ?= runs/demo
# The start is written beside the run folder: --out refuses a folder holding other files.
INIT   ?= $(RUN)_init.yaml

.PHONY: demo test bench clean docs

$(BIN)/paretocal: pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e ".[test]"
	@touch $@

# A full calibration of the 20 bundled KITTI raw frames from a perturbed initial extrinsic.
demo: $(BIN)/paretocal
	@mkdir -p $(dir $(INIT))
	$(BIN)/paretocal perturb $(DATA)/kitti_raw/2011_09_26 --rot 5 --trans 0.2 --seed 1000 --out $(INIT)
	$(BIN)/paretocal calibrate $(DATA)/kitti_raw/2011_09_26 --init $(INIT) --out $(RUN)

test: $(BIN)/paretocal
	PARETOCAL_DATA=$(DATA) $(BIN)/python -m pytest

clean:
	rm -rf $(VENV) runs .pytest_cache site

# The site from docs/ and the docstrings (mkdocs.yml); every warning is an error.
# NO_MKDOCS_2_WARNING silences Material's notice about MkDocs 2, which is not a build warning.
docs: $(BIN)/paretocal
	NO_MKDOCS_2_WARNING=1 $(BIN)/python -m mkdocs build --strict -d site

bench: $(BIN)/paretocal
	PARETOCAL_DATA=$(DATA) $(BIN)/python benchmarks/speed.py --png runs/speed_scaling.png
