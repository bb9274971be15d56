"""The shared roots of the bad-input contract added for issue 38: slender geometry, CSV headers,
non-blocking opens, inputs protected from the run's own writes, output directories that would
overwrite an input, and values read back (batch parts, tables) validated like typed ones."""
import os
import shutil
import sys
import threading
from pathlib import Path

import h5py
import numpy as np
import pytest

from micro.common.files import (NotRegularFile, atomic_write_text, is_regular_file, open_regular,
                       protected_inputs)
from micro.common.validate import InputError, check_header, check_slender

# the packages first: with tests/ on sys.path and the editable install's finder behind it,
# tests/homogenize (a directory without __init__.py) would become a namespace package
import homogenize.cli  # noqa: E402,F401
import micro  # noqa: E402,F401

sys.path.insert(0, str(Path(__file__).resolve().parent))


# --------------------------------------------------------------------------- check_slender
def test_check_slender_names_both_dimensions():
    check_slender("strip", "length_m", 0.02, "thickness_m", 1e-3, 4.0)       # 20: fine
    check_slender("strip", "length_m", 4e-3, "thickness_m", 1e-3, 4.0)       # at the limit
    with pytest.raises(InputError) as exc:
        check_slender("strip", "length_m", 0.02, "thickness_m", 1.0, 4.0, assumption="a beam")
    msg = str(exc.value)
    assert "thickness_m = 1 m" in msg and "length_m = 0.02 m" in msg and "4 x" in msg
    with pytest.raises(InputError):
        check_slender("strip", "length_m", float("nan"), "thickness_m", 1e-3, 4.0)


def test_strip_and_channel_refuse_non_slender_geometry():
    from homogenize.macro.cantilever import Strip
    from homogenize.macro.channel import ChannelGeometry
    Strip(6e-3, 2e-3, 1e-3)                              # the shortest strip of the tests
    Strip(19.369e-3, 5e-3, 1e-3)                         # the seed strip
    with pytest.raises(InputError, match="thickness_m = 1 m.*length_m = 0.019"):
        Strip(0.019, 5e-3, 1.0)
    ChannelGeometry(5e-3, 50e-6, 0.5e-3, 10e-3)          # the seed channel
    ChannelGeometry(0.5e-3, 50e-6, 2e-3, 20e-3)          # the paper's thickest ceiling
    ChannelGeometry(5e-3, 200e-6, 0.5e-3, 5e-3)          # the paper's b and d sweeps
    with pytest.raises(InputError, match="c_m .*a_m"):
        ChannelGeometry(5e-3, 50e-6, 0.5, 10e-3)
    with pytest.raises(InputError, match="b_m .*d_m"):
        ChannelGeometry(5e-3, 50e-6, 0.5e-3, 1e-300)


def test_chain_refuses_before_anything_is_written(tmp_path):
    import bad_input_cases as B
    from homogenize.studies.chain import run_chain
    study = tmp_path / "s.toml"
    study.write_text(B.STUDY)                            # one B_T value: no M_eff(H)
    with pytest.raises(InputError, match="two values"):
        run_chain(study, tmp_path / "out", progress=False)
    study.write_text(B.STUDY.replace("B_T = 0.1", "B_T = [0.1, 0.2]"))
    with pytest.raises(InputError, match="thickness_m"):
        run_chain(study, tmp_path / "out", progress=False, thickness_m=1.0)
    assert not (tmp_path / "out").exists()


# --------------------------------------------------------------------------- check_header
def test_check_header():
    assert check_header("f.csv, row 1", [" radius_m", "count "], required=("radius_m",),
                        one_of=("count", "weight")) == ["radius_m", "count"]
    with pytest.raises(InputError, match="'count' and 'weight' are both given.*ambiguous"):
        check_header("f.csv, row 1", ["radius_m", "count", "weight"], one_of=("count", "weight"))
    with pytest.raises(InputError, match="column 'a': duplicate"):
        check_header("f.csv, row 1", ["a", "b", "a"])
    with pytest.raises(InputError, match="required column 'radius_m'"):
        check_header("f.csv, row 1", ["count"], required=("radius_m",))
    with pytest.raises(InputError, match="needs one of"):
        check_header("f.csv, row 1", ["radius_m"], one_of=("count", "weight"))


def test_histogram_with_count_and_weight_is_refused(tmp_path):
    from micro.particles import Histogram
    f = tmp_path / "h.csv"
    f.write_text("radius_m,count,weight\n1e-6,3,0.5\n2e-6,4,0.5\n")
    with pytest.raises(InputError, match="ambiguous"):
        Histogram.from_csv(f)
    f.write_text("radius_m,count\n1e-6,3\n2e-6,4\n")
    assert len(Histogram.from_csv(f).weights) == 2


# --------------------------------------------------------------------------- open_regular
def test_open_regular_never_blocks_on_a_fifo(tmp_path):
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    done = []

    def attempt():
        try:
            open_regular(fifo)
        except NotRegularFile:
            done.append("refused")

    t = threading.Thread(target=attempt, daemon=True)
    t.start()
    t.join(10)
    if not done:                      # unblock the thread before failing
        with open(fifo, "wb"):
            pass
    assert done == ["refused"]
    assert not is_regular_file(fifo) and not is_regular_file(tmp_path)
    with pytest.raises(NotRegularFile):
        open_regular(tmp_path)
    with pytest.raises(FileNotFoundError):
        open_regular(tmp_path / "nope")
    f = tmp_path / "a.txt"
    f.write_text("abc")
    assert is_regular_file(f)
    with open_regular(f, "r") as fh:
        assert fh.read() == "abc"
    with pytest.raises(ValueError):
        open_regular(f, "w")


# --------------------------------------------------------------------------- outputs vs inputs
def test_atomic_write_refuses_to_replace_a_protected_input(tmp_path):
    src = tmp_path / "notes.md"
    src.write_text("mine")
    link = tmp_path / "other" / "report.md"
    link.parent.mkdir()
    os.link(src, link)                                   # the same file under another name
    with protected_inputs([src]):
        with pytest.raises(InputError, match="input of this command"):
            atomic_write_text(link, "overwritten")
        atomic_write_text(tmp_path / "fresh.md", "ok")   # anything else is written
    assert src.read_text() == "mine"
    atomic_write_text(link, "now allowed")              # protection ends with the block
    assert src.read_text() == "mine"                     # (a new file took the name)


def test_check_output_dir_refuses_inputs_the_run_would_write(tmp_path, monkeypatch):
    from homogenize.cli._common import check_output_dir
    monkeypatch.chdir(tmp_path)
    Path("r").mkdir()
    Path("r/report.md").write_text("notes")
    Path("r/notes.md").write_text("notes")
    writes = ("report.md", "data.png", ".*.tmp")
    with pytest.raises(InputError, match="r/report.md is an input.*--report r"):
        check_output_dir("--report", "r", ["r/report.md"], writes)
    with pytest.raises(InputError, match="input"):                  # through another path
        check_output_dir("--report", str(tmp_path / "r"), ["./r/../r/report.md"], writes)
    check_output_dir("--report", "r", ["r/notes.md"], writes)        # not written: fine
    check_output_dir("--report", "elsewhere", ["r/report.md"], writes)
    with pytest.raises(InputError):                                 # undeclared: all inside
        check_output_dir("--out", "r", ["r/notes.md"], None)


def test_diagnose_keeps_the_discussion_file(tmp_path, monkeypatch):
    import bad_input_cases as B
    from homogenize.cli import main
    monkeypatch.chdir(tmp_path)
    Path("exp.csv").write_text(B.TENSILE_CSV)
    Path("exp.toml").write_text('kind = "tensile"\ndata = "exp.csv"\n')
    Path("r").mkdir()
    Path("r/report.md").write_text("my discussion\n")
    assert main(["diagnose", "exp.toml", "--report", "r", "--discussion", "r/report.md",
                 "--quiet"]) == 2
    assert Path("r/report.md").read_text() == "my discussion\n"
    assert sorted(p.name for p in Path("r").iterdir()) == ["report.md"]


# --------------------------------------------------------------------------- read back
def test_check_part():
    from homogenize.tables.batch import check_part
    good = {"f_eff_N_m3": np.ones(3), "phi_eff": np.array(0.1), "__seed__": 5}
    assert check_part(dict(good), "k", np.array("k"), 5)["phi_eff"] == 0.1
    for bad, match in (({**good, "phi_eff": np.array(np.nan)}, "not finite"),
                       ({**good, "f_eff_N_m3": np.ones(2)}, "shape"),
                       ({**good, "speed": np.array(1.0)}, "unknown quantity"),
                       ({"__seed__": 5}, "no quantities")):
        with pytest.raises(ValueError, match=match):
            check_part(bad, "k", "k", 5)
    with pytest.raises(ValueError, match="seed"):
        check_part(dict(good), "k", "k", 6)
    with pytest.raises(ValueError, match="key"):
        check_part(dict(good), "k", "other", 5)


def test_read_table_refuses_edited_tables(tmp_path):
    from homogenize.tables.batch import read_table
    src = Path(__file__).resolve().parent / "data" / "table_format1.h5"
    read_table(src)
    for attr, value, match in (("confidence", 2.0, "confidence = 2 is not in"),
                               ("confidence", 0.0, "confidence"),
                               ("grid_axes", "{not json", "damaged table")):
        f = tmp_path / f"{attr}.h5"
        shutil.copy(src, f)
        with h5py.File(f, "r+") as h:
            h.attrs[attr] = value
        with pytest.raises(InputError, match=match):
            read_table(f)
    f = tmp_path / "nan.h5"
    shutil.copy(src, f)
    with h5py.File(f, "r+") as h:
        q = next(k for k in h if k.startswith("f_eff"))
        a = h[q][()]
        a.flat[0] = np.nan
        h[q][...] = a
    with pytest.raises(InputError, match="non-finite"):
        read_table(f)


# --------------------------------------------------------------------------- option_needs
def test_check_option_needs():
    import argparse
    from homogenize.cli._common import check_option_needs
    p = argparse.ArgumentParser()
    p.add_argument("--table")
    p.add_argument("--phi", type=float)
    p.add_argument("--kind", default="a")
    p.add_argument("--size", type=float)
    p.add_argument("--vec", type=float, nargs=3, default=(0.0, 0.0, 1.0))
    needs = {"phi": "table", "size": ("kind=b", "!table"), "vec": "kind=c"}
    check_option_needs(p.parse_args([]), p, needs)
    check_option_needs(p.parse_args(["--table", "t", "--phi", "1"]), p, needs)
    check_option_needs(p.parse_args(["--kind", "b", "--size", "1"]), p, needs)
    check_option_needs(p.parse_args(["--vec", "0", "0", "1"]), p, needs)   # the default
    with pytest.raises(InputError, match="--phi has no effect without --table"):
        check_option_needs(p.parse_args(["--phi", "1"]), p, needs)
    with pytest.raises(InputError, match="--size has no effect without --kind b"):
        check_option_needs(p.parse_args(["--size", "1"]), p, needs)
    with pytest.raises(InputError, match="--size and --table are both given.*ambiguous"):
        check_option_needs(p.parse_args(["--kind", "b", "--size", "1", "--table", "t"]), p,
                           needs)
    with pytest.raises(InputError, match="--vec has no effect without --kind c"):
        check_option_needs(p.parse_args(["--vec", "1", "0", "0"]), p, needs)


@pytest.mark.parametrize("text, want", [("0.5", [0.5]), ("0,0.1,0.5", [0, 0.1, 0.5]),
                                        ("0:1:3", [0, 0.5, 1.0]), ("2e-3:1e-3:2", [2e-3, 1e-3]),
                                        (" -1e-3 ", [-1e-3])])
def test_one_syntax_for_a_list_of_values(text, want):
    """relax --B, specimen --B/--gap-m and beam --gap-sweep-m read lists the same way."""
    from homogenize.cli._common import parse_values
    assert np.allclose(parse_values(text, "--x", "m"), want, rtol=0, atol=1e-15)


@pytest.mark.parametrize("text, words", [("0:1:x", "START:STOP:COUNT"), ("a,b", "START:STOP"),
                                         ("0:1:0", "COUNT must be in [1, 1000]"),
                                         ("0:1:2:3", "START:STOP:COUNT")])
def test_list_syntax_errors_name_the_option(text, words):
    from homogenize.cli._common import parse_values
    with pytest.raises(InputError) as exc:
        parse_values(text, "--x", "m")
    assert str(exc.value).startswith("--x") and words in str(exc.value)
