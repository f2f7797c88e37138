"""Output folders (harness.outputs): never write into a user's folder or into the input dataset."""
import pytest

from harness.outputs import MARKER, OutputPathError, guard_not_inside, output_folder


def test_out_folder_guards(tmp_path):
    user = tmp_path / "mine"
    user.mkdir()
    (user / "thesis.tex").write_text("precious")
    with pytest.raises(OutputPathError, match="not empty"):
        output_folder(str(user), overwrite=False)
    with pytest.raises(OutputPathError, match="not made by mpc-actuator"):
        output_folder(str(user), overwrite=True)
    assert (user / "thesis.tex").read_text() == "precious"
    assert not (user / MARKER).exists()
    ours = output_folder(str(tmp_path / "run"), overwrite=False)
    assert (ours / MARKER).is_file()
    (ours / "table.md").write_text("x")
    assert output_folder(str(ours), overwrite=True) == ours       # our own folder may be reused
    with pytest.raises(OutputPathError, match="not empty"):
        output_folder(str(ours), overwrite=False)                   # ... only when allowed
    ds = tmp_path / "dataset"
    ds.mkdir()
    with pytest.raises(OutputPathError, match="inside the input dataset"):
        guard_not_inside(ds / "results", ds)
    with pytest.raises(OutputPathError, match="inside the input dataset"):
        guard_not_inside(ds, ds)
    guard_not_inside(tmp_path / "results", ds)                      # a sibling is fine


def test_a_file_is_not_an_output_folder(tmp_path):
    f = tmp_path / "notes.txt"
    f.write_text("x")
    with pytest.raises(OutputPathError, match="exists and is not a folder"):
        output_folder(f, overwrite=True)
