"""Element-type sensitivity of the clamped strip: the solid elements two FE codes may have used.

The seed paper needed 40 kN/m^3 in Abaqus and 50 kN/m^3 in Elmer for the same 4 mm tip
deflection "on the same mesh". Which elements each code used is not stated. This module solves
the strip of :mod:`homogenize.macro.cantilever` (clamped at ``x = 0``, body force along ``-z``,
half width with the mirror plane ``y = w/2``) on the tensor grid ``(nx, ny, nz)`` with each of
the common solid elements, all in scikit-fem:

================  ====================================================  ======================
name              element and integration                              resembles
================  ====================================================  ======================
``hex8``          trilinear hexahedron, full 2x2x2 Gauss                CalculiX C3D8, Elmer
                                                                        808 (default rule)
``hex8-sri``      trilinear, selective reduced integration: deviatoric  Abaqus C3D8 (constant
                  part 2x2x2, volumetric part at the centre (1 point)   dilatation)
``hex8-r``        trilinear, uniform 1-point integration with           Abaqus/CalculiX C3D8R
                  stiffness hourglass control (below)
``hex20``         20-node serendipity, full 3x3x3                       C3D20, Elmer 820
``hex20-r``       20-node serendipity, reduced 2x2x2                    C3D20R
``hex27``         27-node Lagrange (triquadratic), 3x3x3                Elmer 827
``tet4``          linear tetrahedra (6 per grid cell), exact (1 point)  C3D4, Elmer 504
``tet10``         quadratic tetrahedra, exact (4 points)                C3D10, Elmer 510
================  ====================================================  ======================

The isotropic stiffness is split exactly into a deviatoric and a volumetric part,

    a(u, v) = int 2 mu dev eps(u) : dev eps(v) dV + int kappa div u div v dV,
    kappa = lambda + 2 mu / 3,

so that the integration of each part can be chosen separately.

*Selective reduced integration* (``hex8-sri``) integrates the deviatoric part with 2x2x2 Gauss
points and the volumetric part with the centre point only: one volumetric constraint per
element instead of eight, which removes volumetric locking as nu -> 1/2 but not the parasitic
shear of trilinear elements in bending. For linear elasticity on parallelepipeds it equals the
B-bar (mean dilatation) method.

*Uniform reduced integration* (``hex8-r``) integrates both parts at the centre point. That
stiffness is singular: the twelve hourglass modes (four per component) have zero strain at the
centre. They are stabilised by giving them a fraction ``hourglass`` (epsilon) of their
deviatoric fully integrated stiffness,

    K = K_vol(1 pt) + K_dev(1 pt) + epsilon [K_dev(2x2x2) - K_dev(1 pt)].

On parallelepiped elements (all meshes here) the bracket is positive semi-definite and vanishes
on the constant-strain modes, so it acts on the hourglass modes only. epsilon = 1 gives back
``hex8-sri``; epsilon -> 0 the singular 1-point element. The default :data:`HOURGLASS` = 0.05
is of the size of the stiffness-type hourglass coefficients of explicit codes (0.01-0.1); it
is a choice, not Abaqus' own ("enhanced") hourglass control, and a strip with one or two
layers bends mostly through the hourglass modes, so there the result scales with epsilon. The
CalculiX columns (:func:`ccx_tip`) give the real C3D8R, C3D8I and the others.

The tip deflection is the displacement along the force at the tip centre ``(L, w/2, t/2)``, as
in :func:`homogenize.macro.cantilever.solve_cantilever` (whose P1/P2 results ``tet4``/``tet10``
reproduce to round-off on the same divisions).
"""
from __future__ import annotations

import os
import shutil
import subprocess
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import scipy.sparse.linalg as spla
from skfem import (Basis, BilinearForm, ElementHex1, ElementHex2, ElementHexS2, ElementTetP1,
                   ElementTetP2, ElementVector, MeshHex, asm, condense)
from skfem.helpers import ddot, div, sym_grad, trace

from homogenize.macro.cantilever import Strip
from homogenize.macro.exporters import ExportSpec, parse_ccx_dat, write_deck
from homogenize.macro.fem import FEMSolution, Material, box_mesh, load_vector, \
    probe_displacement
from micro.common.validate import InputError, check_choice, check_range

__all__ = ["ELEMENTS", "CCX_ELEMENTS", "HOURGLASS", "ElementType", "StripTip", "solve_strip",
           "ccx_tip", "ccx_available"]

#: default hourglass stiffness fraction epsilon of ``hex8-r`` (see the module docstring)
HOURGLASS = 0.05


@dataclass(frozen=True)
class ElementType:
    """One element choice: name, human label, what it resembles in Abaqus/CalculiX/Elmer."""
    name: str
    label: str
    resembles: str


#: the scikit-fem element types of :func:`solve_strip`, by name
ELEMENTS = {e.name: e for e in (
    ElementType("hex8", "trilinear hex, full 2x2x2", "CalculiX C3D8, Elmer 808"),
    ElementType("hex8-sri", "trilinear hex, selective reduced (volumetric 1 pt)",
                "Abaqus C3D8 (B-bar)"),
    ElementType("hex8-r", "trilinear hex, 1 pt + hourglass stiffness", "C3D8R"),
    ElementType("hex20", "serendipity hex20, full 3x3x3", "C3D20, Elmer 820"),
    ElementType("hex20-r", "serendipity hex20, reduced 2x2x2", "C3D20R"),
    ElementType("hex27", "Lagrange hex27, 3x3x3", "Elmer 827"),
    ElementType("tet4", "linear tetrahedra (6 per cell)", "C3D4, Elmer 504"),
    ElementType("tet10", "quadratic tetrahedra (6 per cell)", "C3D10, Elmer 510"),
)}

#: CalculiX element types of :func:`ccx_tip` (run by ``ccx`` on the full-width strip)
CCX_ELEMENTS = ("C3D8", "C3D8R", "C3D8I", "C3D20", "C3D20R", "C3D4", "C3D10")


@dataclass(frozen=True)
class StripTip:
    """Tip deflection along the force [m] of one element choice on one grid.

    element : name; divisions : (nx, ny, nz) grid cells (``ny`` across the modelled width);
    n_dof : displacement dofs; n_elements : elements (6 per cell for tetrahedra).
    """
    element: str
    tip_m: float
    divisions: tuple
    n_dof: int
    n_elements: int


def _centre_rule():
    # the 1-point Gauss rule of the reference hexahedron [0, 1]^3 (volume 1)
    return np.array([[0.5], [0.5], [0.5]]), np.array([1.0])


def _forms(material: Material):
    lam, mu = material.lame_Pa
    kappa = lam + 2.0 * mu / 3.0

    @BilinearForm
    def deviatoric(u, v, w):
        eu, ev = sym_grad(u), sym_grad(v)
        return 2.0 * mu * (ddot(eu, ev) - trace(eu) * trace(ev) / 3.0)

    @BilinearForm
    def volumetric(u, v, w):
        return kappa * div(u) * div(v)

    return deviatoric, volumetric


def _grid(strip: Strip, divisions, half: bool):
    nx, ny, nz = divisions
    return (np.linspace(0.0, strip.length_m, nx + 1),
            np.linspace(0.0, strip.width_m / (2 if half else 1), ny + 1),
            np.linspace(0.0, strip.thickness_m, nz + 1))


def _stiffness(name, mesh, material, hourglass):
    """(K, basis) of element ``name``; ``basis`` carries the full rule used for the load."""
    dev, vol = _forms(material)
    if name in ("tet4", "tet10"):
        elem = ElementVector(ElementTetP1() if name == "tet4" else ElementTetP2())
        # exact for the constant (P1) and linear (P2) strains
        basis = Basis(mesh, elem, intorder=1 if name == "tet4" else 2)
        return asm(dev, basis) + asm(vol, basis), basis
    if name.startswith("hex8"):
        elem = ElementVector(ElementHex1())
        full = Basis(mesh, elem, intorder=3)                  # 2x2x2 Gauss
        if name == "hex8":
            return asm(dev, full) + asm(vol, full), full
        one = Basis(mesh, elem, quadrature=_centre_rule())
        if name == "hex8-sri":
            return asm(dev, full) + asm(vol, one), full
        K1 = asm(dev, one)
        return asm(vol, one) + K1 + hourglass * (asm(dev, full) - K1), full
    scalar = ElementHexS2() if name.startswith("hex20") else ElementHex2()
    elem = ElementVector(scalar)
    # intorder 5: 3x3x3 Gauss (full); 3: 2x2x2 Gauss (reduced, the Barlow points)
    full = Basis(mesh, elem, intorder=5)
    if name == "hex20-r":
        red = Basis(mesh, elem, intorder=3)
        return asm(dev, red) + asm(vol, red), full
    return asm(dev, full) + asm(vol, full), full


def solve_strip(strip: Strip, material: Material, f_N_m3: float, element: str, divisions, *,
                half: bool = True, hourglass: float = HOURGLASS) -> StripTip:
    """Tip deflection of the fully clamped strip with element type ``element``.

    Parameters
    ----------
    strip : Strip -- length, width, thickness [m]
    material : Material -- E [Pa], nu [-]
    f_N_m3 : float -- uniform body force along -z [N/m^3]
    element : one of :data:`ELEMENTS`
    divisions : (nx, ny, nz) -- grid cells along length, modelled width, thickness
    half : bool -- model half the width with ``u_y = 0`` on ``y = w/2`` (exact by symmetry)
    hourglass : float in (0, 1] -- hourglass stiffness fraction of ``hex8-r``

    Returns
    -------
    StripTip with the deflection of ``(L, w/2, t/2)`` along the force [m] (positive down).
    """
    check_choice("element", element, tuple(ELEMENTS))
    eps = check_range("hourglass", hourglass, 0.0, 1.0, "", lo_open=True)
    div_ = tuple(int(d) for d in divisions)
    if len(div_) != 3 or min(div_) < 1:
        raise InputError(f"divisions must be three positive integers, got {divisions!r}")
    xs, ys, zs = _grid(strip, div_, half)
    mesh = box_mesh(xs, ys, zs) if element.startswith("tet") else MeshHex.init_tensor(xs, ys, zs)
    K, basis = _stiffness(element, mesh, material, eps)
    rhs = load_vector(basis, np.array([0.0, 0.0, -float(f_N_m3)]))
    tol = 1e-9 * strip.length_m
    fixed = [basis.get_dofs(lambda x: x[0] < tol).all()]
    if half:
        mid = basis.get_dofs(lambda x: x[1] > strip.width_m / 2 - tol).all()
        fixed.append(mid[mid % 3 == 1])          # interleaved dofs: u_y is 3 g + 1
    D = np.unique(np.concatenate(fixed))
    Kc, fc, _, free = condense(K, rhs, D=D)
    u = np.zeros(K.shape[0])
    u[free] = spla.spsolve(Kc.tocsc(), fc)
    # a singular stiffness (unstabilised hourglass modes) shows as a large residual
    res = np.linalg.norm(Kc @ u[free] - fc) / np.linalg.norm(fc)
    if not np.isfinite(res) or res > 1e-6:
        raise RuntimeError(f"{element}: stiffness singular or ill-conditioned (relative "
                           f"residual {res:.3g})")
    sol = FEMSolution(u, basis, "direct")
    L, w, t = strip.length_m, strip.width_m, strip.thickness_m
    # the tip centre, probed just inside the mesh (on the mirror plane with ``half``)
    tip = probe_displacement(sol, np.array([[L * (1 - 1e-9)], [w / 2 * (1 - 1e-9)], [t / 2]]))
    return StripTip(element, float(-tip[2, 0]), div_, int(u.size), int(mesh.t.shape[1]))


# --------------------------------------------------------------------------------------------
# CalculiX

def ccx_available(ccx: str = "ccx") -> bool:
    """Whether the CalculiX solver ``ccx`` is on the PATH."""
    return shutil.which(ccx) is not None


def ccx_tip(strip: Strip, material: Material, f_N_m3: float, element: str, divisions,
            workdir, *, ccx: str = "ccx", timeout_s: float = 600.0) -> StripTip:
    """Tip deflection computed by CalculiX with its own element ``element``.

    The deck is :func:`homogenize.macro.exporters.write_deck` of the full-width strip on the
    grid ``(nx, 2 ny, nz)`` -- the half-strip grid ``divisions`` mirrored, so that the tip
    centre line ``y = w/2`` is a grid line -- written and run in ``workdir``. For linear
    elements with an odd number of layers the tip value is interpolated linearly between the
    nodes of the tip line that bracket ``z = t/2`` (the elements are linear along that edge).

    Raises FileNotFoundError if ``ccx`` is not installed, RuntimeError if it fails.
    """
    check_choice("element", element, CCX_ELEMENTS)
    exe = shutil.which(ccx)
    if exe is None:
        raise FileNotFoundError(f"CalculiX {ccx!r} not installed")
    nx, ny, nz = (int(d) for d in divisions)
    work = Path(workdir)
    work.mkdir(parents=True, exist_ok=True)
    spec = ExportSpec(float(f_N_m3), material.E_Pa, material.nu, material.density_kg_m3)
    stem = f"strip_{element}_{nx}x{2 * ny}x{nz}"
    deck = write_deck("cantilever", "abaqus", spec, strip, work / f"{stem}.inp",
                      element=element, divisions=(nx, 2 * ny, nz))
    env = dict(os.environ, OMP_NUM_THREADS="1", CCX_NPROC_EQUATION_SOLVER="1")
    r = subprocess.run([exe, "-i", stem], cwd=work, capture_output=True, text=True,
                       timeout=timeout_s, env=env)
    dat = work / f"{stem}.dat"
    if r.returncode != 0 or not dat.exists():
        raise RuntimeError(f"ccx failed on {stem}: {(r.stdout + r.stderr)[-800:]}")
    u = parse_ccx_dat(dat.read_text())
    ids = deck.mesh.node_sets["NTIP"]
    z = deck.mesh.nodes_m[ids, 2]
    uz = np.array([u[int(i) + 1][2] for i in ids])
    tip = float(np.interp(strip.thickness_m / 2.0, z, uz)) if len(ids) > 1 else float(uz[0])
    n_el = len(deck.mesh.elements)
    return StripTip(element, -tip, (nx, 2 * ny, nz), 3 * len(deck.mesh.nodes_m), n_el)
