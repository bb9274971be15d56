"""The RVE dataclass and its HDF5 I/O (micro/rve.py)."""
import dataclasses

import h5py
import numpy as np
import pytest

from micro import RVE, InputError, generate_rve
from micro.particles import CoreShell


@pytest.fixture(scope="module")
def rve():
    return generate_rve(0.05, 150, 4, composition=CoreShell(shell_m=2e-9),
                        arrangement="clusters", cluster_size=5, agglomerated_fraction=0.4)


def test_roundtrip_is_exact_with_units(tmp_path, rve):
    path = rve.save(tmp_path / "sub" / "r.h5")
    back = RVE.load(path)
    assert back == rve
    assert back.params == rve.params and back.seed == 4
    with h5py.File(path) as f:
        assert f["centers_m"].attrs["units"] == "m"
        assert f["m_sat_Am2"].attrs["units"] == "A m^2"
        assert f["mass_kg"].attrs["units"] == "kg"
        assert f.attrs["box_m_units"] == "m"
        assert f["cluster_id"].dtype == np.int64
    # Atomic write: nothing but the file itself is left in the directory.
    assert [p.name for p in path.parent.iterdir()] == ["r.h5"]


def test_seed_none_roundtrip(tmp_path):
    r = RVE.from_spheres(1e-6, [[0, 0, 0], [5e-7, 5e-7, 5e-7]], [1e-8, 2e-8])
    assert r.seed is None
    assert RVE.load(r.save(tmp_path / "n.h5")).seed is None


def test_derived_quantities():
    r = RVE.from_spheres(2e-7, [[1e-8, 1e-8, 1e-8], [1e-7, 1e-7, 1e-7]], [1e-8, 2e-8])
    v = 4 / 3 * np.pi * np.array([1e-8, 2e-8]) ** 3
    assert r.n == 2 and r.volume_m3 == pytest.approx(8e-21)
    np.testing.assert_allclose(r.particle_volumes_m3, v)
    assert r.phi == pytest.approx(v.sum() / 8e-21)
    np.testing.assert_allclose(r.m_sat_Am2 / r.mass_kg, 178.0)
    assert r.specific_moment_Am2_kg == pytest.approx(178.0)
    np.testing.assert_allclose(r.minimum_image(np.array([1.5e-7, -1.2e-7, 0.5e-7])),
                               [-0.5e-7, 0.8e-7, 0.5e-7], rtol=1e-12)


def test_immutable_and_wrapped(rve):
    with pytest.raises(dataclasses.FrozenInstanceError):
        rve.box_m = 1.0
    with pytest.raises(ValueError):
        rve.centers_m[0, 0] = 0.0          # read-only array
    r = RVE.from_spheres(1e-6, [[1.2e-6, -0.1e-6, 1e-6]], [1e-8])
    np.testing.assert_allclose(r.centers_m, [[0.2e-6, 0.9e-6, 0.0]], atol=1e-18)
    assert np.all((r.centers_m >= 0) & (r.centers_m < r.box_m))


@pytest.mark.parametrize("change, words", [
    (dict(box_m=-1.0), ["box_m", "> 0"]),
    (dict(centers_m=np.zeros((3, 2))), ["centers_m", "(N, 3)"]),
    (dict(radii_m=np.zeros(2)), ["radii_m"]),
    (dict(core_radii_m=np.array([1.0, 1.0])), ["core_radii_m"]),
    (dict(params={"x": object()}), ["params", "JSON"]),
])
def test_constructor_rejects_bad_fields(change, words):
    kw = dict(box_m=1e-6, centers_m=np.zeros((2, 3)), radii_m=np.full(2, 1e-8),
              core_radii_m=np.full(2, 1e-8), m_sat_Am2=np.ones(2), mass_kg=np.ones(2),
              cluster_id=np.full(2, -1), seed=1, params={})
    kw.update(change)
    with pytest.raises(InputError) as exc:
        RVE(**kw)
    for w in words:
        assert w in str(exc.value)


def test_load_refuses_foreign_or_broken_files(tmp_path, rve):
    with pytest.raises(InputError, match="does not exist"):
        RVE.load(tmp_path / "missing.h5")
    (tmp_path / "text.h5").write_text("not hdf5")
    with pytest.raises(InputError, match="not a readable HDF5"):
        RVE.load(tmp_path / "text.h5")
    with h5py.File(tmp_path / "other.h5", "w") as f:
        f["x"] = 1
    with pytest.raises(InputError, match="not a mapsim RVE"):
        RVE.load(tmp_path / "other.h5")
    p = rve.save(tmp_path / "nm.h5")
    with h5py.File(p, "a") as f:
        f["radii_m"].attrs["units"] = "nm"
    with pytest.raises(InputError, match="radii_m.*units"):
        RVE.load(p)


def test_failed_save_keeps_previous_file(tmp_path, rve, monkeypatch):
    p = rve.save(tmp_path / "keep.h5")
    before = p.read_bytes()

    def boom(*a, **k):
        raise RuntimeError("disk full")

    monkeypatch.setattr(h5py.Group, "create_dataset", boom)
    with pytest.raises(RuntimeError):
        rve.save(p)
    assert p.read_bytes() == before
    assert [q.name for q in tmp_path.iterdir()] == ["keep.h5"]
