"""The executed examples (docs/examples/*.ipynb, issue 23 part 3): Jupyter notebooks that use the public API
(:mod:`harness.api`) the way a researcher would.

* default suite: every notebook is valid nbformat, its code compiles, and every ``api.NAME`` it uses is a name of
  :mod:`harness.api` (a renamed or removed entry point fails here, in a second);
* ``-m slow``: every notebook is executed top to bottom by a Jupyter kernel (nbclient, as ``jupyter nbconvert
  --execute`` or nbmake would), in a temporary folder, with the FMUs built for the session; the notebooks check
  their own results with ``assert`` (identified model within 5 % of the measured stroke, the hidden effect named
  and its parameter within 10 %, held-out error halved, the FMU equal to the Python model, both controllers
  tracking within 0.1 mm), so a notebook that runs but computes nonsense fails. Each takes one to three minutes:
  too long for the default suite's budget.
"""
from __future__ import annotations

import ast
import os
import re
from pathlib import Path

import nbformat
import pytest

from harness import api

REPO = Path(__file__).resolve().parents[1]
NOTEBOOKS = sorted((REPO / "docs" / "examples").glob("*.ipynb"))


def _code(nb) -> str:
    return "\n".join(c.source for c in nb.cells if c.cell_type == "code")


def test_there_are_three_examples():
    names = [p.stem for p in NOTEBOOKS]
    assert len(names) >= 3
    assert any("identify" in n for n in names) and any("diagnose" in n for n in names) \
        and any("loop" in n for n in names)


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.stem)
def test_notebook_is_valid_and_uses_the_public_api(path):
    nb = nbformat.read(path, as_version=4)
    nbformat.validate(nb)
    for cell in nb.cells:
        if cell.cell_type == "code":
            assert not cell.outputs and cell.execution_count is None, f"{path.name}: stored outputs (strip them)"
            ast.parse(cell.source, filename=path.name)
    used = set(re.findall(r"\bapi\.([A-Za-z_]\w*)", _code(nb)))
    assert used, f"{path.name} does not use harness.api"
    assert used <= set(api.__all__), f"{path.name} uses names harness.api does not have: {used - set(api.__all__)}"
    for node in ast.walk(ast.parse(_code(nb))):      # project imports only through harness.api
        if isinstance(node, ast.ImportFrom) and node.module and node.module.split(".")[0] in ("harness", "fmu_src"):
            assert node.module == "harness" and [a.name for a in node.names] == ["api"], (path.name, node.module)


@pytest.mark.slow
@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.stem)
def test_notebook_executes(path, tmp_path, fmu_path, controller_fmu_path, monkeypatch):
    from nbclient import NotebookClient
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")]))
    monkeypatch.setenv("MPC_ACTUATOR_FMU", str(fmu_path))
    monkeypatch.setenv("MPC_CONTROLLER_FMU", str(controller_fmu_path))
    monkeypatch.setenv("MPLBACKEND", "Agg")
    nb = nbformat.read(path, as_version=4)
    NotebookClient(nb, timeout=900, kernel_name="python3", resources={"metadata": {"path": str(tmp_path)}}).execute()
    errors = [o for c in nb.cells if c.cell_type == "code" for o in c.outputs if o.output_type == "error"]
    assert not errors
    assert any(c.outputs for c in nb.cells if c.cell_type == "code")
