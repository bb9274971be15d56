"""Tunable microfluidic channel (seed paper, Section 3.2 and Fig. 4).

A PDMS block on a rigid glass base; a straight channel of width ``a`` and height ``b`` is cut
into its underside and runs through the whole block length ``d``; the polymer above the channel
(the ceiling) has thickness ``c``; side walls of width ``wall`` flank the channel. The block is
bonded to the glass (``u = 0`` on its bottom face), all other faces are traction-free (the end
faces ``x = 0, d`` included). The magnetic body force ``f`` acts along ``-z`` (towards the glass
and the magnet underneath), pulling the ceiling into the channel.

Coordinates: ``x`` along the channel (length ``d``), ``y`` across it, ``z`` up from the glass.
The two mirror planes ``x = d/2`` and ``y = W/2`` are used to solve a quarter of the block.

Optionally a uniform liquid pressure ``pressure_Pa`` (gauge) acts on the polymer faces of the
channel (ceiling and side walls), pushing them away from the channel: the ceiling bulges up.
The glass is rigid, so the pressure on the channel floor does nothing.

Outputs per case: the largest ceiling deflection (at the centre), the relative reduction of
the channel cross-section at mid-length, ``-Delta A / (a b)`` with
``Delta A = oint u . n ds`` over the channel outline (outward normal of the channel), and the
ceiling deflection profile across the half width at mid-length (used by
:mod:`homogenize.macro.flow` for the gap of the deformed channel).
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

from skfem import FacetBasis, LinearForm, asm
from skfem.models.elasticity import linear_elasticity

from homogenize.macro.fem import (FEMSolution, Material, _solve_free, box_mesh, probe_displacement,
                                  vector_basis)
from micro.common.validate import check_choice, check_finite, check_positive, check_slender

__all__ = ["ChannelGeometry", "ChannelResult", "solve_channel"]


#: smallest channel length / height d / b (lubrication along the channel; the studies use >= 25)
MIN_LENGTH_TO_HEIGHT = 4.0
#: largest ceiling thickness / channel width c / a (the paper's sweep reaches 4)
CEILING_MAX_PER_WIDTH = 10.0
#: smallest side-wall width / (b + c) (the default wall is at least 2 (b + c))
MIN_WALL_PER_HEIGHT = 0.1


@dataclass(frozen=True)
class ChannelGeometry:
    """Channel width ``a_m``, height ``b_m``, ceiling thickness ``c_m``, length ``d_m`` [m];
    ``wall_m`` side-wall width [m] (None: ``max(a/2, 2 (b + c))``)."""
    a_m: float
    b_m: float
    c_m: float
    d_m: float
    wall_m: float | None = None

    def __post_init__(self):
        for name in ("a_m", "b_m", "c_m", "d_m"):
            check_positive(name, getattr(self, name), "m")
        if self.wall_m is not None:
            check_positive("wall_m", self.wall_m, "m")
        # the model: a thin ceiling over a wide, flat channel that is long against its height
        # (lubrication along d); a ratio far outside these is a value in the wrong unit
        check_slender("channel", "d_m (length)", self.d_m, "b_m (height)", self.b_m,
                      MIN_LENGTH_TO_HEIGHT, assumption="lubrication along the channel")
        check_slender("channel", "a_m (width)", self.a_m, "c_m (ceiling thickness)", self.c_m,
                      1.0 / CEILING_MAX_PER_WIDTH,
                      assumption="a ceiling that bends over the channel")
        if self.wall_m is not None:
            check_slender("channel", "wall_m (side wall)", self.wall_m,
                          "(b_m + c_m) (channel height and ceiling)", self.b_m + self.c_m,
                          MIN_WALL_PER_HEIGHT, assumption="side walls that carry the ceiling")

    @property
    def wall(self) -> float:
        return self.wall_m if self.wall_m is not None else max(self.a_m / 2, 2 * (self.b_m +
                                                                                  self.c_m))


@dataclass(frozen=True)
class ChannelResult:
    """max_deflection_m : ceiling deflection at the channel centre, along the force [m];
    area_reduction : relative loss of the mid-length cross-section [-];
    closes : True if the linear deflection exceeds the channel height (contact not modelled);
    divisions : (nx, ny, nz) hexahedra of the quarter model; n_dof; order;
    pressure_Pa : liquid gauge pressure on the channel's polymer faces [Pa];
    ceiling_y_m : tuple, shape (n,) -- distance from the side wall across the half width,
    0 ... a/2 [m]; ceiling_deflection_m : tuple, shape (n,) -- mid-length ceiling deflection
    towards the glass at those points [m] (negative: bulged up)."""
    a_m: float
    b_m: float
    c_m: float
    d_m: float
    wall_m: float
    f_N_m3: float
    max_deflection_m: float
    area_reduction: float
    closes: bool
    divisions: tuple
    n_dof: int
    order: int
    pressure_Pa: float = 0.0
    ceiling_y_m: tuple = ()
    ceiling_deflection_m: tuple = ()

    def to_dict(self) -> dict:
        return asdict(self)


def _graded(x0, x1, n, ratio: float = 1.0):
    """Nodes of n intervals on [x0, x1] growing geometrically, last/first size = ``ratio``."""
    if n == 1 or ratio == 1.0:
        return np.linspace(x0, x1, n + 1)
    h = (ratio ** (1.0 / (n - 1))) ** np.arange(n)
    return x0 + (x1 - x0) * np.concatenate(([0.0], np.cumsum(h) / h.sum()))


def _divisions(g: ChannelGeometry, nc: int, aspect: float):
    h = g.c_m / nc
    na = max(4, math.ceil(g.a_m / 2 / (aspect * h)))          # half channel width
    nw = max(3, min(12, math.ceil(g.wall / (2 * aspect * h))))  # graded wall
    nd = max(3, min(16, math.ceil(g.d_m / 2 / (2 * aspect * h))))
    nb = max(1, math.ceil(g.b_m / (aspect * h)))
    return nd, nw, na, nb, nc


def solve_channel(geometry: ChannelGeometry, material: Material, f_N_m3: float, *, order=2,
                  nc: int = 2, aspect: float = 4.0, gravity_m_s2: float = 0.0,
                  solver: str = "auto", pressure_Pa: float = 0.0) -> ChannelResult:
    """Linear-elastic deformation of the channel block under the body force ``f_N_m3`` and a
    liquid pressure ``pressure_Pa`` in the channel.

    Parameters
    ----------
    geometry : ChannelGeometry -- a, b, c, d, wall [m]
    material : Material -- E [Pa], nu, density [kg/m^3]
    f_N_m3 : float -- magnetic body force towards the glass [N/m^3]
    order : 1 or 2 -- tetrahedron degree
    nc : int -- element layers through the ceiling; other sizes follow with ``aspect``
    gravity_m_s2 : float -- self-weight ``density g`` added to the force [m/s^2]
    solver : "auto" | "direct" | "amg-pcg"
    pressure_Pa : float -- uniform gauge pressure of the liquid on the ceiling and side walls
        [Pa] (>= 0 or < 0: suction pulls the ceiling down)
    """
    f = check_positive("f_N_m3", f_N_m3, "N/m^3", allow_zero=True)
    p_liq = float(check_finite("pressure_Pa", pressure_Pa, "Pa"))
    g_acc = check_positive("gravity_m_s2", gravity_m_s2, "m/s^2", allow_zero=True)
    nc = int(check_positive("nc", nc, ""))
    g = geometry
    a, b, c, d, s = g.a_m, g.b_m, g.c_m, g.d_m, g.wall
    nd, nw, na, nb, nc = _divisions(g, nc, aspect)
    # quarter model: x in [0, d/2], y in [0, s + a/2]
    xs = _graded(0.0, d / 2, nd, ratio=2.0)   # finer at the free end x = 0
    ys = np.concatenate((_graded(0.0, s, nw, ratio=0.25)[:-1],  # finer towards the channel
                         np.linspace(s, s + a / 2, na + 1)))
    zs = np.concatenate((np.linspace(0.0, b, nb + 1)[:-1], np.linspace(b, b + c, nc + 1)))
    mesh = box_mesh(xs, ys, zs)
    mid = mesh.p[:, mesh.t].mean(axis=1)
    in_channel = (mid[1] > s) & (mid[2] < b)
    mesh = mesh.remove_elements(np.nonzero(in_channel)[0])
    tol = 1e-9 * max(a, b, c, d)
    ymax = s + a / 2

    def fixed(basis):
        bottom = basis.get_dofs(lambda x: x[2] < tol).all()
        sym_x = basis.get_dofs(lambda x: x[0] > d / 2 - tol).all()
        sym_y = basis.get_dofs(lambda x: x[1] > ymax - tol).all()
        # mirror planes: normal displacement zero (interleaved dofs: component i is 3 g + i)
        return np.unique(np.concatenate((bottom, sym_x[sym_x % 3 == 0], sym_y[sym_y % 3 == 1])))

    total = f + material.density_kg_m3 * g_acc
    sol = _solve_loaded(mesh, material, total, p_liq, fixed, order, solver,
                        ceiling=lambda x: (np.abs(x[2] - b) < tol) & (x[1] > s - tol),
                        wall=lambda x: (np.abs(x[1] - s) < tol) & (x[2] < b + tol))
    # mid-length section, probed just inside the polymer
    eps = 1e-7 * min(b, c, a)
    xm = d / 2 - eps
    yc = np.linspace(s, ymax, 4 * na + 1)
    zw = np.linspace(0.0, b, 4 * nb + 1)
    ceiling = probe_displacement(sol, np.vstack((np.full_like(yc, xm), yc, np.full_like(yc, b + eps))))
    wall = probe_displacement(sol, np.vstack((np.full_like(zw, xm), np.full_like(zw, s - eps), zw)))
    # half outline (mirror at y = W/2): ceiling contributes int u_z dy, the left wall -int u_y dz
    dA_half = np.trapezoid(ceiling[2], yc) - np.trapezoid(wall[1], zw)
    area_red = -2.0 * dA_half / (a * b)
    delta = float(-ceiling[2, -1])
    return ChannelResult(a, b, c, d, s, total, delta, float(area_red), bool(delta >= b),
                         (nd, nw + na, nb + nc), sol.n_dof, order, p_liq,
                         tuple(float(v) for v in yc - s),
                         tuple(float(-v) for v in ceiling[2]))


def _solve_loaded(mesh, material: Material, f_down_N_m3: float, pressure_Pa: float, fixed,
                  order: int, solver: str, ceiling, wall) -> FEMSolution:
    """Linear elasticity under the body force ``-f e_z`` and the liquid pressure on the channel.

    The liquid pushes on the polymer along its outward normal ``n`` with traction ``-p n``:
    ``+p e_z`` on the ceiling (``n = -e_z``), ``-p e_y`` on the side wall of the quarter model
    (``n = +e_y``). ``ceiling`` and ``wall`` select those boundary facets by their midpoints.
    """
    check_choice("solver", solver, ("auto", "direct", "amg-pcg"))
    basis = vector_basis(mesh, order)
    lam, mu = material.lame_Pa
    K = asm(linear_elasticity(lam, mu), basis)

    @LinearForm
    def body(v, w):
        return -f_down_N_m3 * v[2]

    rhs = asm(body, basis)
    if pressure_Pa != 0.0:
        # traction quadrature exact for P2 traces (a constant load times a quadratic)
        qorder = 2 * order

        @LinearForm
        def lift(v, w):
            return pressure_Pa * v[2]

        @LinearForm
        def push(v, w):
            return -pressure_Pa * v[1]

        for sel, form in ((ceiling, lift), (wall, push)):
            facets = mesh.facets_satisfying(sel, boundaries_only=True)
            rhs = rhs + asm(form, FacetBasis(mesh, basis.elem, facets=facets, intorder=qorder))
    u, name, it, res = _solve_free(K, rhs, fixed(basis), solver, 1e-10, basis)
    return FEMSolution(u, basis, name, it, res)
