"""The streaming CSV reader (harness.data.csvfile.read_csv / parse_csv) against the reader it
replaced (tests/data/csv_reference.py, which held the whole file): same arrays for valid files,
the same DataFormatError (message, line, column) for broken ones, whatever the block size.

Hypothesis draws whole CSV files of every test: random rows and cell spellings, comments and
blank lines anywhere, LF/CRLF/CR line ends (mixed), a BOM, quoted cells, extra named columns
(numeric or text, some non-ASCII), empty trailing columns; broken files get one to three
defects (a bad cell at a random row and column, time not increasing, a duplicate or negative
gap, a wrong cell count, decimal commas, a missing column, invalid UTF-8 at a random byte
offset), so the precedence between several problems is compared too. The block size is drawn
down to 1 byte, so block boundaries fall inside BOMs, CRLFs, multi-byte characters and cells.

Fast profile (derandomized, a few seconds) by default; the deep one under ``-m deep``.
Memory: tracemalloc peak of reading a 400k-row file against the size of its arrays.
"""
from __future__ import annotations

import io
import tracemalloc

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from harness.data.csvfile import parse_csv, read_csv
from harness.data.format import COLUMNS, SWEEP_TESTS, TESTS, DataFormatError
from tests.data import csv_reference as ref

DISPLAY = "ds/S1/T.csv"


def outcome(fn):
    """What a reader does with a file: its arrays (bit for bit) or its error."""
    try:
        out = fn()
    except DataFormatError as e:
        return ("error", str(e), e.line, e.column, e.column_name)
    except Exception as e:   # noqa: BLE001 - anything else must be the same too
        return ("exception", type(e).__name__, str(e))
    return ("ok", {k: (v.dtype.str, v.tobytes()) for k, v in out.items()})


def reference(raw: bytes, test: str):
    return outcome(lambda: ref.parse_csv(ref.decode_text(raw, DISPLAY), test, DISPLAY))


def check_same(raw: bytes, test: str, chunk_size: int):
    want = reference(raw, test)
    got = outcome(lambda: read_csv(io.BytesIO(raw), test, DISPLAY, chunk_size=chunk_size))
    assert got == want, f"read_csv, chunk_size={chunk_size}, file {raw!r}"
    try:
        text = ref.decode_text(raw, DISPLAY)
    except DataFormatError:
        return want
    got = outcome(lambda: parse_csv(text, test, DISPLAY, chunk_size=chunk_size))
    assert got == want, f"parse_csv, chunk_size={chunk_size}, file {raw!r}"
    return want


# ====================================================================== strategies
BAD_CELLS = ["x", "", " ", "nan", "-inf", "Infinity", "1e999", "-1e400", "1,5", "1.2.3", "--1", "1e", ".",
             "0x10", "1_000", "\u0663", "\uff11.5", "6.0V", "1 2", "\x0b2\x0c", '"3"', '"1,5"', "1.5\u00a0"]
EXTRA_COLUMNS = ["temp_C", "note", "field_T", "\u00b5_x"]
EXTRA_VALUES = ["1", "-2.5e-3", "ok", "", "a b", "\u00b5T", "n/a"]


def spell(draw, v: float, exact: bool) -> str:
    """A cell for the value v: repr or %.17g (exact), or a shorter spelling; signs, spaces, quotes."""
    forms = [repr(v), f"{v:.17g}"] + ([] if exact else [f"{v:g}", f"{v:.3e}", f"{v:.2f}"])
    s = draw(st.sampled_from(forms))
    if not s.startswith("-") and draw(st.booleans()) and draw(st.booleans()):
        s = "+" + s
    r = draw(st.integers(0, 9))
    if r == 0:
        s = f" {s}  "
    elif r == 1:
        s = f'"{s}"'
    return s


@st.composite
def csv_files(draw, broken: bool = False):
    test = draw(st.sampled_from(TESTS))
    cols = list(COLUMNS[test])
    sweep = test in SWEEP_TESTS
    extra = draw(st.lists(st.sampled_from(EXTRA_COLUMNS), unique=True, max_size=2))
    header = draw(st.permutations(cols + extra))
    trailing = draw(st.integers(0, 2)) if draw(st.booleans()) else 0
    n = draw(st.integers(1 if sweep else 2, 30))
    finite = st.floats(-1e6, 1e6, allow_nan=False, width=64)
    data = {c: draw(st.lists(finite, min_size=n, max_size=n)) for c in cols}
    if sweep:
        data["gap_mm"] = draw(st.lists(st.floats(0, 50, allow_nan=False), min_size=n, max_size=n, unique=True))
    else:
        data["time_s"] = sorted(draw(st.lists(finite, min_size=n, max_size=n, unique=True)))
    exact = not broken or draw(st.booleans())
    rows = []
    for i in range(n):
        row = [spell(draw, data[h][i], exact) if h in data else draw(st.sampled_from(EXTRA_VALUES))
               for h in header]
        row += draw(st.lists(st.sampled_from(["", " "]), max_size=trailing))
        rows.append(row)
    head = list(header) + [""] * trailing
    # ---- defects
    defects = draw(st.lists(st.sampled_from(["cell", "order", "count", "decimal", "column", "utf8"]),
                            min_size=1, max_size=3)) if broken else []
    for d in defects:
        r = draw(st.integers(0, n - 1))
        if d == "cell" and rows[r]:           # (a row may have lost cells to an earlier defect)
            j = draw(st.integers(0, len(rows[r]) - 1))
            rows[r][j] = draw(st.sampled_from(BAD_CELLS))
        elif d == "order" and n >= 2:
            key = "gap_mm" if sweep else "time_s"
            j, r = header.index(key), max(r, 1)
            k = draw(st.integers(0, r - 1))
            if j < len(rows[r]) and j < len(rows[k]):
                rows[r][j] = draw(st.sampled_from([rows[k][j], "-1", "-0.5e1"]))
        elif d == "count":
            if draw(st.booleans()) and len(rows[r]) > 1:
                del rows[r][draw(st.integers(0, len(rows[r]) - 1))]
            else:
                rows[r].insert(draw(st.integers(0, len(rows[r]))), draw(st.sampled_from(["7", "", "x"])))
        elif d == "decimal":
            rows[r] = [c.replace(".", ",") for c in rows[r]]
        elif d == "column":
            j = draw(st.integers(0, len(header) - 1))
            head[j] = draw(st.sampled_from(["time_ms", "displacment_mm", "Current (A)", "", head[j - 1]]))
    # ---- lines: comments and blank lines anywhere, line ends mixed or not
    comment = st.sampled_from(["# comment", "#", "  # indented, with comma,", "# \u00b5 non-ASCII", "", "   ",
                               "\t"])
    lines = draw(st.lists(comment, max_size=2)) + [",".join(head)]
    for row in rows:
        lines += draw(st.lists(comment, max_size=1)) if draw(st.integers(0, 3)) == 0 else []
        lines.append(",".join(row))
    lines += draw(st.lists(comment, max_size=2))
    ends = draw(st.sampled_from(["\n", "\r\n", "\r", "mixed"]))
    text = ""
    for line in lines:
        text += line + (draw(st.sampled_from(["\n", "\r\n", "\r"])) if ends == "mixed" else ends)
    if draw(st.booleans()):
        text = text.rstrip("\r\n")
    raw = (b"\xef\xbb\xbf" if draw(st.booleans()) else b"") + text.encode("utf-8")
    if "utf8" in defects:
        k = draw(st.integers(0, len(raw)))
        raw = raw[:k] + draw(st.sampled_from([b"\xff", b"\xc3", b"\xe2\x82", b"\x80", b"\xed\xa0\x80"])) + raw[k:]
    return test, raw


CHUNK_SIZES = st.sampled_from([1, 2, 3, 5, 8, 13, 40, 100, 1000, 1 << 20])
FAST = settings(max_examples=120, derandomize=True, deadline=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
DEEP = settings(max_examples=4000, deadline=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])


@FAST
@given(csv_files(), CHUNK_SIZES)
def test_valid_files_same_arrays(case, chunk_size):
    test, raw = case
    kind = check_same(raw, test, chunk_size)[0]
    # a valid file stays valid: only quoted cells with spaces around the quotes are not numbers
    assert kind == "ok" or b' "' in raw or b'" ' in raw


@FAST
@given(csv_files(broken=True), CHUNK_SIZES)
def test_broken_files_same_error(case, chunk_size):
    test, raw = case
    check_same(raw, test, chunk_size)


@pytest.mark.deep
@DEEP
@given(csv_files(), CHUNK_SIZES)
def test_valid_files_same_arrays_deep(case, chunk_size):
    test, raw = case
    check_same(raw, test, chunk_size)


@pytest.mark.deep
@DEEP
@given(csv_files(broken=True), CHUNK_SIZES)
def test_broken_files_same_error_deep(case, chunk_size):
    test, raw = case
    check_same(raw, test, chunk_size)


# ====================================================================== block boundaries, by hand
TRICKY = ("\ufeff# \u00b5 comment, with comma\r\n\r\n"
          "time_s,voltage_V,current_A,displacement_mm,note,,\r\n"
          "0,1.5,2,3,\u00b5,,\r"
          "0.001,+1.5e-3, 2 ,3,ok\n"
          "# in between\n"
          '0.002,"4",5,6,"a,b", ,\r\n'
          "0.003,1,1,1,,,\n"
          "0.004,1,1,1,,\n").encode("utf-8")


@pytest.mark.parametrize("chunk_size", range(1, 60))
def test_every_block_boundary(chunk_size):
    want = check_same(TRICKY, "T3", chunk_size)
    assert want[0] == "ok"


@pytest.mark.parametrize("chunk_size", [1, 2, 3, 4, 7, 64])
@pytest.mark.parametrize("bad, line", [(0, 1), (3, 1), (5, 1), (7, 2), (8, 2), (10, 3), (45, 4)])
def test_invalid_byte_names_line_and_file_offset(chunk_size, bad, line):
    raw = b"\xef\xbb\xbfa,b\r\nc\rtime_s,voltage_V,current_A,force_N\n0,0,0,0\n1,1,1,1\n"
    raw = raw[:bad] + b"\xff" + raw[bad:]
    with pytest.raises(DataFormatError) as ei:
        read_csv(io.BytesIO(raw), "T8", DISPLAY, chunk_size=chunk_size)
    assert (ei.value.line, str(ei.value)) == (line, f"{DISPLAY}, line {line}: not valid UTF-8 text "
                                                    f"(byte offset {bad})")
    assert reference(raw, "T8")[1] == str(ei.value)


def test_error_after_many_blocks_names_its_line(tmp_path):
    n = 20000
    lines = ["time_s,voltage_V,current_A,displacement_mm"] + [f"{i * 1e-3!r},1,2,3" for i in range(n)]
    lines[15001] = "0.5,1,2,3"                       # line 15002: before the previous line's time
    path = tmp_path / "T3.csv"
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(DataFormatError) as ei:
        read_csv(path, "T3", chunk_size=4096)
    assert ei.value.line == 15002
    assert f"time not strictly increasing: 0.5 s after {14999 * 1e-3!r} s on line 15001" in str(ei.value)
    assert str(ei.value) == reference(path.read_bytes(), "T3")[1].replace(DISPLAY, str(path))


# ====================================================================== memory
def test_peak_memory_is_a_small_multiple_of_the_arrays(tmp_path):
    n = 400_000
    rng = np.random.default_rng(7)
    a = np.column_stack([np.arange(n) * 1e-4, rng.standard_normal((n, 3))])
    path = tmp_path / "T3.csv"
    with open(path, "w") as fh:
        fh.write("# synthetic\ntime_s,voltage_V,current_A,displacement_mm\n")
        np.savetxt(fh, a, delimiter=",", fmt="%.17g")
    tracemalloc.start()
    try:
        out = read_csv(path, "T3")
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    for k, c in enumerate(COLUMNS["T3"]):
        assert np.array_equal(out[c], a[:, k])
    arrays = sum(v.nbytes for v in out.values())
    assert arrays == a.nbytes
    assert peak <= 3 * arrays, f"peak {peak / 1e6:.1f} MB for {arrays / 1e6:.1f} MB of arrays"


# ====================================================================== precedence, by hand
HEAD = "time_s,voltage_V,current_A,displacement_mm\n"


@pytest.mark.parametrize("chunk_size", [1, 30, 1 << 20])
@pytest.mark.parametrize("body, fragment", [
    ("0,x,0,0\n1,1,1\n2,2,2,2\n", "line 3: wrong number of cells"),          # count before an earlier bad cell
    ("0,x,0,0\n1,1,y,1\nz,2,2,2\n", "line 4, column 1 ('time_s'): non-numeric value 'z'"),   # format column order
    ("0,1,1,1\n0,nan,1,1\n", "line 3, column 2 ('voltage_V')"),              # a bad cell before the time order
    ("0,1,1,1,\n", "too few data rows: 1"),                                   # row count before the cell count
    ("0,1,1,1\n0,1,1\n\xff", "line 4: not valid UTF-8"),                     # an invalid byte before everything
])
def test_precedence_of_problems(chunk_size, body, fragment):
    raw = HEAD.encode() + body.encode("utf-8", "surrogateescape").replace(b"\xc3\xbf", b"\xff")
    want = check_same(raw, "T3", chunk_size)
    assert want[0] == "error" and fragment in want[1]
