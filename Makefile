# Two entry points (see README): `make run` and `make test`.
PYTHON ?= python3.11
VENV   := .venv
PY     := $(VENV)/bin/python
OUT    ?= out

.PHONY: setup fmu run test clean

$(VENV)/.installed: pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[test]'
	touch $@

setup: $(VENV)/.installed

fmu: setup
	$(PY) build_fmu.py

run: fmu
	$(VENV)/bin/mpc-actuator run --out $(OUT) --overwrite

test: fmu
	$(PY) -m pytest -q -n 2 --dist loadfile -p no:cacheprovider tests

clean:
	rm -rf $(VENV) mpc_actuator.fmu $(OUT)
