"""The executed examples (docs/examples/*.ipynb, issue 23 part 3): Jupyter notebooks that use the public API
(:mod:`harness.api`) the way a researcher would.

* every notebook is valid nbformat, its code compiles, every ``api.NAME`` it uses is a name of :mod:`harness.api`,
  and it has one papermill-style ``parameters`` cell (tagged ``parameters``) assigning the names the quick profile
  sets;
* default suite, the quick profile: every notebook is executed top to bottom by a Jupyter kernel (nbclient, as
  ``jupyter nbconvert --execute``, nbmake or papermill would), in a temporary folder with the FMUs built for the
  session, with small parameters injected after its ``parameters`` cell as papermill does (:data:`QUICK`: one sample,
  ``tests/fixtures/clean-500hz-1-sample``, a tiny NSGA-II, one worker); a cell that raises fails the test;
* ``-m slow``: the same, with the notebooks' own parameters (three samples, one to three minutes each).

The notebooks check their own results with ``assert`` in both profiles (identified model within 5 % of the
measured stroke, the hidden effect named and its parameter within 10 %, held-out error halved, the FMU equal to the
Python model, both controllers tracking the 1 mm sine within 15 % and 3 %), so a notebook that runs but computes
nonsense fails.
"""
from __future__ import annotations

import ast
import csv
import json
import os
import re
from pathlib import Path

import nbformat
import pytest

from harness import api

REPO = Path(__file__).resolve().parents[1]
NOTEBOOKS = sorted((REPO / "docs" / "examples").glob("*.ipynb"))
QUICK_DATASET = "tests/fixtures/clean-500hz-1-sample"
# The quick profile: {notebook stem: {parameter: value}}, injected after the notebook's "parameters" cell.
QUICK = {
    "01-identify-your-data": {"DATASET": QUICK_DATASET, "POP_SIZE": 8, "N_GEN": 3, "WORKERS": 1},
    "02-diagnose-and-extend": {"SAMPLES": ((20, 45),), "WORKERS": 1},
    "03-close-the-loop": {"DATASET": QUICK_DATASET, "POP_SIZE": 8, "N_GEN": 3, "WORKERS": 1},
}


def _code(nb) -> str:
    return "\n".join(c.source for c in nb.cells if c.cell_type == "code")


def parameters_cell(nb) -> int:
    """Index of the notebook's one cell tagged ``parameters``."""
    found = [i for i, c in enumerate(nb.cells) if "parameters" in c.metadata.get("tags", [])]
    assert len(found) == 1, f"expected one cell tagged 'parameters', found {len(found)}"
    assert nb.cells[found[0]].cell_type == "code"
    return found[0]


def with_parameters(nb, params: dict):
    """The notebook with a cell assigning ``params`` after its ``parameters`` cell (papermill's injection)."""
    i = parameters_cell(nb)
    if not params:
        return nb
    cell = nbformat.v4.new_code_cell("\n".join(f"{k} = {v!r}" for k, v in params.items()))
    cell.metadata["tags"] = ["injected-parameters"]
    nb.cells.insert(i + 1, cell)
    return nb


def execute(path: Path, tmp_path: Path, params: dict, fmu_path, controller_fmu_path, monkeypatch):
    """Run the notebook top to bottom in ``tmp_path`` (nbclient raises CellExecutionError on a cell that raises)."""
    from nbclient import NotebookClient
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")]))
    monkeypatch.setenv("MPC_ACTUATOR_FMU", str(fmu_path))
    monkeypatch.setenv("MPC_CONTROLLER_FMU", str(controller_fmu_path))
    monkeypatch.setenv("MPLBACKEND", "Agg")
    nb = with_parameters(nbformat.read(path, as_version=4), params)
    NotebookClient(nb, timeout=900, kernel_name="python3", resources={"metadata": {"path": str(tmp_path)}}).execute()
    errors = [o for c in nb.cells if c.cell_type == "code" for o in c.outputs if o.output_type == "error"]
    assert not errors
    assert all(c.execution_count is not None for c in nb.cells if c.cell_type == "code")     # every cell ran
    return nb


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


def test_quick_profile_sets_parameters_the_notebooks_have():
    assert set(QUICK) == {p.stem for p in NOTEBOOKS}
    for path in NOTEBOOKS:
        nb = nbformat.read(path, as_version=4)
        assigned = {t.id for node in ast.walk(ast.parse(nb.cells[parameters_cell(nb)].source))
                    if isinstance(node, ast.Assign) for tgt in node.targets
                    for t in ([tgt] if isinstance(tgt, ast.Name) else getattr(tgt, "elts", [])) if isinstance(t, ast.Name)}
        assert set(QUICK[path.stem]) <= assigned, (path.name, set(QUICK[path.stem]) - assigned)


def test_quick_dataset_is_a_reduced_copy_of_the_example_dataset():
    """The quick profile's dataset is W20-D45 of clean-500hz-3-samples, its gap sweeps thinned to every fifth gap."""
    full, quick = REPO / "tests" / "fixtures" / "clean-500hz-3-samples", REPO / QUICK_DATASET
    m_full, m_quick = (json.loads((d / "manifest.json").read_text()) for d in (full, quick))
    assert [s["id"] for s in m_quick["samples"]] == ["W20-D45"]
    assert m_quick["samples"][0] == next(s for s in m_full["samples"] if s["id"] == "W20-D45")
    assert m_quick["rig"] == m_full["rig"]
    for spec in m_quick["samples"][0]["tests"].values():
        rows_full = list(csv.reader((full / spec["file"]).open()))
        rows_quick = list(csv.reader((quick / spec["file"]).open()))
        if spec["file"].endswith(("T1.csv", "T7.csv")):
            rows_full = rows_full[:1] + [r for r in rows_full[1:] if float(r[0]) % 5 == 0]
            assert len(rows_quick) == 7
        assert rows_quick == rows_full


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.stem)
def test_notebook_executes_quick(path, tmp_path, fmu_path, controller_fmu_path, monkeypatch):
    execute(path, tmp_path, QUICK[path.stem], fmu_path, controller_fmu_path, monkeypatch)


@pytest.mark.slow
@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.stem)
def test_notebook_executes(path, tmp_path, fmu_path, controller_fmu_path, monkeypatch):
    execute(path, tmp_path, {}, fmu_path, controller_fmu_path, monkeypatch)
