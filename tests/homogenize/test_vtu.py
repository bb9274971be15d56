"""VTU / PVD output of the cell fields: VTK tensor order, component names, field data, one file
per load case; read back with meshio against the cell result's mean stresses."""
import shutil
import subprocess
import xml.etree.ElementTree as ET
from types import SimpleNamespace

import numpy as np
import pytest

from homogenize.cell._output import (VTK_COMPONENT_NAMES, VTK_TENSOR_ORDER, all_cases,
                                     local_fields, write_pvd, write_vtu)
from homogenize.cell.problem import CASES, homogenize_rve
from micro.common.validate import InputError

meshio = pytest.importorskip("meshio")

L = 1e-6
CENTRES = np.array([[0.3, 0.35, 0.4], [0.62, 0.55, 0.66]]) * L
FORCES = np.array([[1.0, 0.5, 0.8], [-0.2, 0.3, -1.1]]) * 1e-12


@pytest.fixture(scope="module")
def result():
    # 8^3 voxels, two particles, all six strain cases and the magnetic case, tight tolerance
    # so that the mean of the local stresses equals the variational means to ~1e-8
    return homogenize_rve(SimpleNamespace(box_m=L, centers_m=CENTRES,
                                          radii_m=np.full(2, 0.15 * L)), 8,
                          forces_N=FORCES, keep_fields=True, tol=1e-11)


def _tensor_from_vtk(stress6):
    """(N, 6) in VTK order -> (N, 3, 3)."""
    T = np.zeros((len(stress6), 3, 3))
    for k, (r, c) in enumerate(VTK_TENSOR_ORDER):
        T[:, r, c] = T[:, c, r] = stress6[:, k]
    return T


def test_pvd_has_every_load_case_and_components_follow_vtk_order(result, tmp_path):
    paths = write_pvd(tmp_path / "cell.pvd", result, B_T=0.1, gradB_T_per_m=[0, 0, 1.78],
                      law="langevin")
    assert all_cases(result) == CASES + ("magnetic",)
    assert [p.name for p in paths] == ["cell.pvd"] + [f"cell_{c}.vtu" for c in all_cases(result)]
    coll = ET.parse(paths[0]).getroot()
    entries = coll.find("Collection").findall("DataSet")
    assert [e.get("name") for e in entries] == list(all_cases(result))
    assert [int(e.get("timestep")) for e in entries] == list(range(7))
    assert all((tmp_path / e.get("file")).exists() for e in entries)
    for k, case in enumerate(all_cases(result)):
        m = meshio.read(tmp_path / f"cell_{case}.vtu")
        s6 = m.cell_data["stress_Pa"][0]
        assert s6.shape == (8 ** 3, 6)
        # voxels have equal volume: the mean over cells is the volume average
        mean = _tensor_from_vtk(s6).mean(axis=0)
        if case == "magnetic":
            # elastic part of the magnetic stress (the force-moment part is not a field)
            ref = result.stress_mag_elastic_Pa
        else:
            # column of C_eff: mean stress of the unit-strain case, Voigt -> tensor
            col = result.C_eff_Pa[:, CASES.index(case)]
            ref = np.zeros((3, 3))
            for v, (r, c) in enumerate(((0, 0), (1, 1), (2, 2), (1, 2), (0, 2), (0, 1))):
                ref[r, c] = ref[c, r] = col[v]
        scale = np.abs(ref).max()
        # tolerance: CG stopped at 1e-11; the variational C and the plain mean stress differ by
        # the square vs the first power of that error, far below 1e-6 relative
        assert np.abs(mean - ref).max() < 1e-6 * scale, case
        # the file's component k is the VTK component (XX, YY, ZZ, XY, YZ, XZ) of the local
        # tensor: check it against the stress computed here, voxel by voxel
        sig = local_fields(result, case)["stress_Pa"].reshape(-1, 3, 3)
        for c_i, (r, c) in enumerate(VTK_TENSOR_ORDER):
            assert np.allclose(s6[:, c_i], sig[:, r, c], rtol=1e-12, atol=1e-12 * scale)
        fd = m.field_data
        assert bytes(fd["load_case"].astype(np.uint8)).decode() == case
        assert int(np.ravel(fd["load_case_index"])[0]) == k
        assert bytes(fd["law"].astype(np.uint8)).decode() == "langevin"
        assert np.allclose(np.ravel(fd["B_T"]), [0, 0, 0.1])
        assert np.allclose(np.ravel(fd["gradB_T_per_m"]), [0, 0, 1.78])
        assert int(np.ravel(fd["voxels"])[0]) == 8
        assert np.isclose(float(np.ravel(fd["box_m"])[0]), L)
        units = bytes(fd["units"].astype(np.uint8)).decode()
        assert "stress_Pa: Pa" in units and "gradB_T_per_m: T/m" in units


def test_vtu_names_the_tensor_components(result, tmp_path):
    p = tmp_path / "one.vtu"
    write_vtu(p, result, "g23")
    arrays = {da.get("Name"): da for da in ET.parse(p).iter("DataArray")}
    da = arrays["stress_Pa"]
    assert da.get("NumberOfComponents") == "6"
    assert tuple(da.get(f"ComponentName{k}") for k in range(6)) == VTK_COMPONENT_NAMES
    # shear case g23: the only large mean component is sigma_yz, stored under "YZ" (index 4)
    m = meshio.read(p)
    mean = m.cell_data["stress_Pa"][0].mean(axis=0)
    assert np.argmax(np.abs(mean)) == VTK_COMPONENT_NAMES.index("YZ")
    # no magnetic state given: no B, no gradB, law "none"
    assert "B_T" not in m.field_data and "gradB_T_per_m" not in m.field_data
    assert bytes(m.field_data["law"].astype(np.uint8)).decode() == "none"


def test_bad_inputs(result, tmp_path):
    with pytest.raises(InputError, match="load case 'e99'"):
        write_pvd(tmp_path / "x.pvd", result, cases=["e99"])
    with pytest.raises(InputError, match="B_T"):
        write_vtu(tmp_path / "x.vtu", result, "e11", B_T=[1.0, 2.0])


PVPYTHON = shutil.which("pvpython")
XVFB = shutil.which("xvfb-run")


@pytest.mark.skipif(PVPYTHON is None or XVFB is None,
                    reason="pvpython (Debian python3-paraview, ~250 packages) or xvfb-run not "
                           "installed: ParaView read-back not checked; meshio read-back above "
                           "checks the same component order")
def test_paraview_reads_the_component_names(result, tmp_path):
    p = tmp_path / "cell_g23.vtu"
    write_vtu(p, result, "g23")
    script = tmp_path / "read.py"
    script.write_text(
        "from paraview.simple import XMLUnstructuredGridReader\n"
        f"r = XMLUnstructuredGridReader(FileName=[{str(p)!r}])\n"
        "r.UpdatePipeline()\n"
        "a = r.CellData['stress_Pa']\n"
        "print('NAMES', ','.join(a.GetComponentName(k) for k in range(6)))\n"
        "print('RANGE_YZ', *a.GetRange(4))\n")
    out = subprocess.run([XVFB, "-a", PVPYTHON, str(script)], capture_output=True, text=True,
                         timeout=300)
    assert out.returncode == 0, out.stderr
    names = [ln for ln in out.stdout.splitlines() if ln.startswith("NAMES")][0].split()[1]
    assert tuple(names.split(",")) == VTK_COMPONENT_NAMES
