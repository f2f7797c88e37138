# Two entry points (see README): `make run` and `make test`; `make docs` builds the documentation site.
PYTHON ?= python3.11
VENV   := .venv
PY     := $(VENV)/bin/python
OUT    ?= out

.PHONY: setup fmu native run test docs clean

$(VENV)/.installed: pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[test,docs]'
	@# the FMU's status shim (fmu_shim/) needs a C compiler; without cc/gcc take Zig's from PyPI
	@if [ -z "$$CC" ] && ! command -v cc >/dev/null 2>&1 && ! command -v gcc >/dev/null 2>&1; then \
		echo "no C compiler found: installing the PyPI package ziglang (zig cc) for the FMU's status shim"; \
		$(PY) -m pip install --quiet -e '.[cc]'; fi
	touch $@

setup: $(VENV)/.installed

# the controller FMU (harness/control, `mpc-actuator control`): rebuilt only when its sources change
mpc_controller.fmu: $(VENV)/.installed build_fmu.py fmu_shim/fmi2_status_shim.c $(wildcard fmu_src/*.py)
	$(PY) build_fmu.py --controller

# the native FMU (C generated from fmu_src at build time: no Python needed on the target; docs/fmu.md)
mpc_actuator_native.fmu: $(VENV)/.installed build_fmu.py $(wildcard fmu_shim/native/*) $(wildcard fmu_src/*.py)
	$(PY) build_fmu.py --native

native: mpc_actuator_native.fmu

fmu: setup mpc_controller.fmu
	$(PY) build_fmu.py

run: fmu
	$(VENV)/bin/mpc-actuator run --out $(OUT) --overwrite

test: fmu
	$(PY) -m pytest -q -n 2 --dist loadfile -p no:cacheprovider tests

# the documentation site (mkdocs.yml, docs/), every warning an error, into site/
docs: setup
	$(VENV)/bin/mkdocs build --strict --site-dir site

clean:
	rm -rf $(VENV) mpc_actuator.fmu mpc_controller.fmu mpc_actuator_native.fmu $(OUT) site
