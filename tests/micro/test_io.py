"""Committed-result helpers of micro.common.files: rounding to meaningful digits, data digests, HDF5
agreement to round-off."""
import h5py
import numpy as np
import pytest

from micro.common.files import RESULT_DIGITS, data_digest, hdf5_agree, round_floats, write_json


def test_round_floats_keeps_structure_and_rounds_to_significant_digits():
    obj = {"a": 0.007454880229115496, "b": [1, 2.5e-300, np.float64(np.pi)],
           "c": np.arange(3) / 3.0, "d": (True, None, "x", np.int64(7)), "e": float("nan")}
    r = round_floats(obj)
    assert r["a"] == 0.00745488 and r["b"] == [1, 2.5e-300, 3.14159]
    assert r["c"] == [0.0, 0.333333, 0.666667]
    assert r["d"] == (True, None, "x", 7) and type(r["d"][3]) is int
    assert np.isnan(r["e"])
    again = round_floats(r)                                   # idempotent
    assert {k: v for k, v in again.items() if k != "e"} == {k: v for k, v in r.items() if k != "e"}
    assert round_floats(12345678.9, 3) == 1.23e7


def test_round_off_of_another_cpu_does_not_change_the_rounded_value():
    """The issue's example: ...496 against ...497 in the 17th digit."""
    a, b = 0.007454880229115496, 0.007454880229115497
    assert a != b and round_floats(a) == round_floats(b)
    # a value RESULT_DIGITS digits away changes it
    assert round_floats(a) != round_floats(a * (1 + 10.0 ** -(RESULT_DIGITS - 1)))


def test_data_digest_follows_rounded_numbers_and_the_drawing_code(tmp_path):
    src = tmp_path / "draw.py"
    src.write_text("x = 1\n")
    d = data_digest({"y": [0.007454880229115496]}, src)
    assert d == data_digest({"y": [0.007454880229115497]}, src)
    assert d != data_digest({"y": [0.0074549]}, src)
    src.write_text("x = 2\n")
    assert d != data_digest({"y": [0.007454880229115496]}, src)


def test_write_json_digits(tmp_path):
    write_json(tmp_path / "a.json", {"x": 1 / 3}, digits=4)
    assert (tmp_path / "a.json").read_text() == '{\n  "x": 0.3333\n}\n'


def _h5(path, x, attr="v1", extra=False):
    with h5py.File(path, "w") as h:
        h.attrs["version"] = attr
        d = h.create_dataset("x", data=x)
        d.attrs["units"] = "Pa"
        h.create_dataset("n", data=np.arange(4))
        if extra:
            h.create_dataset("y", data=x)


@pytest.mark.parametrize("change, agree", [
    (lambda x: x * (1 + 1e-13), True),          # round-off
    (lambda x: x + 1e-12 * np.nanmax(np.abs(x)), True),
    (lambda x: x * (1 + 1e-6), False),          # a real change
    (lambda x: np.where(np.arange(x.size) == 1, np.nan, x), False),
])
def test_hdf5_agree_to_round_off_only(tmp_path, change, agree):
    x = np.array([1.0, 2e5, -3e-20, np.nan])
    _h5(tmp_path / "a.h5", x)
    _h5(tmp_path / "b.h5", change(x))
    assert hdf5_agree(tmp_path / "a.h5", tmp_path / "b.h5", 1e-8) is agree


def test_hdf5_agree_compares_attributes_names_and_unreadable_files(tmp_path):
    x = np.linspace(0, 1, 5)
    _h5(tmp_path / "a.h5", x)
    _h5(tmp_path / "b.h5", x, attr="v2")
    _h5(tmp_path / "c.h5", x, extra=True)
    _h5(tmp_path / "d.h5", x)
    (tmp_path / "e.h5").write_text("not hdf5")
    assert hdf5_agree(tmp_path / "a.h5", tmp_path / "d.h5", 1e-8)
    assert not hdf5_agree(tmp_path / "a.h5", tmp_path / "b.h5", 1e-8)
    assert not hdf5_agree(tmp_path / "a.h5", tmp_path / "c.h5", 1e-8)
    assert not hdf5_agree(tmp_path / "a.h5", tmp_path / "e.h5", 1e-8)
