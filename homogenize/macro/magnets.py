"""Real magnet fields over the specimen, and the body force they exert along the strip.

A strip is bent by a real magnet, not by a uniform gradient: ``B(x)`` and ``grad |B|(x)`` vary
along it. The field of a source is computed with magpylib (analytic fields of uniformly
magnetized cuboids and cylinders and of circular current loops, SI units):

* :class:`PermanentMagnet` -- a cuboid or cylinder with its remanence ``B_r = mu0 |M|`` [T] and
  magnetization direction;
* :class:`Coil` -- an air-core solenoid of ``turns`` circular loops carrying ``current_A``,
  stacked at the midpoints of ``turns`` equal slices of its length (the midpoint rule of the
  current sheet: on the axis it differs from the continuous solenoid by ~``(pitch / R)^2 / 24``
  relative). An iron core, as in the seed paper's electromagnet, is not modelled.

:func:`sample_field` returns ``B`` and ``grad |B|`` at points. :func:`body_force_along_strip`
returns the magnetic body force density along a :class:`~homogenize.macro.cantilever.Strip`,
which occupies ``[0, L] x [0, w] x [0, t]`` in the lab frame (clamp at ``x = 0``, load along
``-z``; the magnet is placed in that frame).

Body force. The specimen's magnetization is taken along the local field, ``M = M_eff(|H_in|)
H / |H|``, with ``M_eff`` a material law (e.g. interpolated from a batch table,
:func:`tabulated_magnetization`). The net force on a body comes from the applied field only (its
own field exerts no net force), so per volume ``f = mu0 (M . grad) H_a``; the applied field is
curl-free outside the source, hence ``(H . grad) H = grad(|H|^2 / 2)`` and, with ``M`` along
``H``, ``f = mu0 M_eff grad |H_a| = M_eff grad |B_a|`` [A/m * T/m = N/m^3]. The specimen's own
demagnetization (factor ``N`` for the field direction, :mod:`micro.demag`) lowers the internal
field: ``H_in = |H_a| - N M_eff(H_in)``, solved per point (bisection on ``[0, |H_a|]``, to
round-off). In the linear regime ``M = chi H_in`` this gives ``M = chi |H_a| / (1 + N chi)``: the
force is lowered by the factor ``1 / (1 + N chi)``.

Units: m, T, A/m, A, N/m^3 throughout.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import magpylib
import numpy as np
from scipy.constants import mu_0 as MU0
from scipy.integrate import simpson
from scipy.spatial.transform import Rotation

from homogenize.macro.cantilever import Strip
from homogenize.macro.closed_form import BodyForceProfile
from micro.common.validate import InputError, check_choice, check_finite, check_positive, check_range

__all__ = ["PermanentMagnet", "Coil", "StripBodyForce", "sample_field", "body_force_along_strip",
           "linear_magnetization", "tabulated_magnetization"]

#: relative finite-difference step for grad |B|, times the source's smallest dimension (see
#: :func:`sample_field`)
FD_STEP_REL = 1e-4


def _unit(name, v):
    v = np.asarray(check_finite(name, v, ""), dtype=float)
    if v.shape != (3,):
        raise InputError(f"{name} must be a 3-vector, got shape {v.shape}")
    n = float(np.linalg.norm(v))
    if n == 0.0:
        raise InputError(f"{name} must be a non-zero 3-vector, got {tuple(v)}")
    return tuple(float(c) for c in v / n)


def _vec3(name, v, unit="m"):
    v = np.asarray(check_finite(name, v, unit), dtype=float)
    if v.shape != (3,):
        raise InputError(f"{name} must be a 3-vector [{unit}], got shape {v.shape}")
    return tuple(float(c) for c in v)


def _rotation_from_z(axis) -> Rotation:
    """The rotation taking the local z axis onto ``axis`` (unit), about ``z x axis``."""
    a = np.asarray(axis, float)
    c = float(a[2])
    if c > 1.0 - 1e-15:
        return Rotation.identity()
    if c < -1.0 + 1e-15:
        return Rotation.from_rotvec([math.pi, 0.0, 0.0])
    k = np.cross([0.0, 0.0, 1.0], a)
    return Rotation.from_rotvec(k / np.linalg.norm(k) * math.acos(max(-1.0, min(1.0, c))))


@dataclass(frozen=True)
class PermanentMagnet:
    """A uniformly magnetized cuboid or cylinder.

    Parameters
    ----------
    shape : "cuboid" | "cylinder"
    dimensions_m : tuple -- cuboid: edge lengths (a, b, c) along the body's local x, y, z [m];
        cylinder: (diameter, height), the height along the local z (the cylinder's axis) [m]
    remanence_T : float -- remanent polarization ``B_r = mu0 |M|`` [T], in (0, 3]
    position_m : 3-vector -- centre of the magnet in the lab (strip) frame [m]
    direction : 3-vector -- magnetization direction in the lab frame (normalised) [-]
    axis : 3-vector -- the body's local z axis in the lab frame (normalised): the cylinder's
        axis, the cuboid's c edge; the body is turned by the smallest rotation taking z there
    """

    shape: str
    dimensions_m: tuple
    remanence_T: float
    position_m: tuple = (0.0, 0.0, 0.0)
    direction: tuple = (0.0, 0.0, 1.0)
    axis: tuple = (0.0, 0.0, 1.0)

    def __post_init__(self):
        check_choice("shape", self.shape, ("cuboid", "cylinder"))
        n = 3 if self.shape == "cuboid" else 2
        dims = np.asarray(check_finite("dimensions_m", self.dimensions_m, "m"), float)
        if dims.shape != (n,):
            what = "(a, b, c)" if n == 3 else "(diameter, height)"
            raise InputError(f"dimensions_m of a {self.shape} must be {what} [m], got "
                             f"{self.dimensions_m!r}")
        for d in dims:
            check_positive("dimensions_m", d, "m")
        # the strongest permanent magnets (NdFeB) reach ~1.5 T; 3 T is a generous bound
        check_range("remanence_T", self.remanence_T, 0.0, 3.0, "T", lo_open=True)
        object.__setattr__(self, "dimensions_m", tuple(float(d) for d in dims))
        object.__setattr__(self, "remanence_T", float(self.remanence_T))
        object.__setattr__(self, "position_m", _vec3("position_m", self.position_m))
        object.__setattr__(self, "direction", _unit("direction", self.direction))
        object.__setattr__(self, "axis", _unit("axis", self.axis))

    @property
    def length_scale_m(self) -> float:
        """Smallest dimension [m]."""
        return min(self.dimensions_m)


@dataclass(frozen=True)
class Coil:
    """An air-core solenoid of circular loops.

    Parameters
    ----------
    radius_m : float -- loop radius [m], > 0
    length_m : float -- winding length along the axis [m], >= 0 (0: all loops in one plane)
    turns : int -- number of loops, >= 1
    current_A : float -- current in each loop [A] (sign: right-handed about ``axis``)
    position_m : 3-vector -- centre of the winding in the lab frame [m]
    axis : 3-vector -- the coil's axis in the lab frame (normalised)
    """

    radius_m: float
    length_m: float
    turns: int
    current_A: float
    position_m: tuple = (0.0, 0.0, 0.0)
    axis: tuple = (0.0, 0.0, 1.0)

    def __post_init__(self):
        check_positive("radius_m", self.radius_m, "m")
        check_positive("length_m", self.length_m, "m", allow_zero=True)
        if not float(self.turns).is_integer() or int(self.turns) < 1:
            raise InputError(f"turns must be an integer >= 1, got {self.turns!r}")
        check_finite("current_A", self.current_A, "A")
        if self.current_A == 0:
            raise InputError("current_A must be non-zero [A], got 0")
        object.__setattr__(self, "radius_m", float(self.radius_m))
        object.__setattr__(self, "length_m", float(self.length_m))
        object.__setattr__(self, "turns", int(self.turns))
        object.__setattr__(self, "current_A", float(self.current_A))
        object.__setattr__(self, "position_m", _vec3("position_m", self.position_m))
        object.__setattr__(self, "axis", _unit("axis", self.axis))

    @property
    def length_scale_m(self) -> float:
        """Smallest dimension [m]: the radius, or the length if shorter (and non-zero)."""
        return min(self.radius_m, self.length_m) if self.length_m > 0 else self.radius_m

    def loop_offsets_m(self) -> np.ndarray:
        """Axial positions of the loops relative to the centre, shape (turns,) [m]."""
        k = np.arange(self.turns)
        return (k + 0.5) / self.turns * self.length_m - 0.5 * self.length_m


def _magpylib_source(source):
    rot = _rotation_from_z(source.axis)
    pos = np.asarray(source.position_m)
    if isinstance(source, PermanentMagnet):
        pol = source.remanence_T * rot.inv().apply(np.asarray(source.direction))
        cls = magpylib.magnet.Cuboid if source.shape == "cuboid" else magpylib.magnet.Cylinder
        return cls(dimension=source.dimensions_m, polarization=pol, position=pos,
                   orientation=rot)
    if isinstance(source, Coil):
        loops = [magpylib.current.Circle(current=source.current_A,
                                         diameter=2.0 * source.radius_m,
                                         position=pos + rot.apply([0.0, 0.0, dz]),
                                         orientation=rot)
                 for dz in source.loop_offsets_m()]
        return magpylib.Collection(*loops)
    raise InputError(f"source must be a PermanentMagnet or a Coil, got {type(source).__name__}")


def _points(points_m):
    p = np.asarray(check_finite("points_m", points_m, "m"), dtype=float)
    if p.ndim != 2 or p.shape[1] != 3:
        raise InputError(f"points_m must have shape (N, 3) [m], got {p.shape}")
    return p


def _getB(src, p):
    return np.asarray(magpylib.getB(src, p), dtype=float).reshape(p.shape)


def sample_field(source, points_m):
    """Flux density and the gradient of its magnitude at points.

    Parameters
    ----------
    source : PermanentMagnet or Coil
    points_m : array_like, shape (N, 3) -- observation points in the lab frame [m], outside
        the source

    Returns
    -------
    B_T : ndarray, shape (N, 3) -- flux density [T]
    grad_absB_T_per_m : ndarray, shape (N, 3) -- gradient of ``|B|`` [T/m]

    Notes
    -----
    ``grad |B|`` by central differences with the step ``h = FD_STEP_REL * s``, ``s`` the
    source's smallest dimension. At a distance ``d`` from the source the field varies on the
    scale ``d``: the truncation error is ~``(h / d)^2 / 6 = 1.7e-9 (s / d)^2`` relative and the
    cancellation error ~``eps_B d / h`` with magpylib's relative accuracy ``eps_B`` ~ 1e-14
    (closed forms, elliptic integrals to round-off), i.e. ~1e-10 ``d / s``: both below 1e-7 for
    ``s / 100 < d < 1e3 s``. The test checks 1e-6 against analytic derivatives.
    """
    p = _points(points_m)
    src = _magpylib_source(source)
    h = FD_STEP_REL * source.length_scale_m
    n = p.shape[0]
    # one magpylib call for the points and their six neighbours
    shifts = np.vstack([np.zeros(3), h * np.eye(3), -h * np.eye(3)])
    allp = (p[None, :, :] + shifts[:, None, :]).reshape(-1, 3)
    Ball = _getB(src, allp).reshape(7, n, 3)
    absB = np.linalg.norm(Ball, axis=2)
    grad = (absB[1:4] - absB[4:7]).T / (2.0 * h)
    return Ball[0], grad


# --------------------------------------------------------------------------------------------
# overlap of the source with the strip

def _inside_source(source, p, rel=1e-9):
    """Points strictly inside the source (a coil: on its winding, the cylindrical shell)."""
    rot = _rotation_from_z(source.axis)
    loc = rot.inv().apply(p - np.asarray(source.position_m))
    if isinstance(source, PermanentMagnet):
        d = np.asarray(source.dimensions_m)
        if source.shape == "cuboid":
            return np.all(np.abs(loc) < 0.5 * d * (1 - rel), axis=1)
        rho = np.hypot(loc[:, 0], loc[:, 1])
        return (rho < 0.5 * d[0] * (1 - rel)) & (np.abs(loc[:, 2]) < 0.5 * d[1] * (1 - rel))
    return loc


def _box_grid(lo, hi, n):
    axes = [np.linspace(a, b, n) for a, b in zip(lo, hi)]
    return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)


def _check_overlap(source, strip: Strip, n=25):
    """Refuse a source that overlaps the strip (sampled on n^3 grids of both bodies)."""
    L, w, t = strip.length_m, strip.width_m, strip.thickness_m
    box = np.array([L, w, t])
    sp = _box_grid(np.zeros(3), box, n)
    what = None
    if isinstance(source, PermanentMagnet):
        hit = _inside_source(source, sp).any()
        if not hit:
            # points of the magnet strictly inside the strip
            rot = _rotation_from_z(source.axis)
            d = np.asarray(source.dimensions_m)
            if source.shape == "cuboid":
                loc = _box_grid(-0.5 * d, 0.5 * d, n)
            else:
                loc = _box_grid((-0.5 * d[0], -0.5 * d[0], -0.5 * d[1]),
                                (0.5 * d[0], 0.5 * d[0], 0.5 * d[1]), n)
                loc = loc[np.hypot(loc[:, 0], loc[:, 1]) <= 0.5 * d[0]]
            mp = rot.apply(loc) + np.asarray(source.position_m)
            hit = np.all((mp > 1e-9 * box) & (mp < box * (1 - 1e-9)), axis=1).any()
        what = f"the {source.shape} magnet"
    else:
        loc = _inside_source(source, sp)
        rho = np.hypot(loc[:, 0], loc[:, 1])
        slab = np.abs(loc[:, 2]) <= 0.5 * source.length_m + 1e-9 * source.radius_m
        R = source.radius_m
        # the winding (radius R, |z| <= length/2) cuts the strip if strip points of that slab
        # lie on both sides of it, or on it
        hit = slab.any() and ((rho[slab].min() < R < rho[slab].max())
                              or np.any(np.abs(rho[slab] - R) <= 1e-9 * R))
        what = "the coil's winding"
    if hit:
        raise InputError(f"{what} at position_m={tuple(source.position_m)} overlaps the strip "
                         f"[0, {L:g}] x [0, {w:g}] x [0, {t:g}] m; place the source outside the "
                         f"specimen")


# --------------------------------------------------------------------------------------------
# magnetization laws of the specimen

def linear_magnetization(chi: float, Ms_A_m: float = math.inf):
    """``M(H) = min(chi H, Ms)`` [A/m] for ``H`` [A/m] >= 0: linear, optionally saturating.

    ``chi`` is the specimen's intrinsic (demagnetization-free) susceptibility [-], > 0.
    """
    chi = check_positive("chi", chi, "")
    Ms = check_positive("Ms_A_m", Ms_A_m, "A/m") if math.isfinite(Ms_A_m) else math.inf

    def M(H_A_m):
        return np.minimum(chi * np.asarray(H_A_m, float), Ms)
    return M


def tabulated_magnetization(H_A_m, M_A_m):
    """Magnetization law interpolated linearly in a table, no extrapolation.

    Parameters
    ----------
    H_A_m : array_like, shape (n,) -- field, strictly increasing, >= 0 [A/m]
    M_A_m : array_like, shape (n,) -- magnetization along the field [A/m], >= 0

    Returns
    -------
    callable -- ``M(H)`` [A/m]; a field outside ``[H_A_m[0], H_A_m[-1]]`` raises
    :class:`InputError`, except below the first entry when it is 0 (then ``M`` is 0 there)
    """
    H = np.array(check_finite("H_A_m", H_A_m, "A/m"), float)
    Mt = np.array(check_finite("M_A_m", M_A_m, "A/m"), float)
    if H.ndim != 1 or H.size < 2 or Mt.shape != H.shape:
        raise InputError(f"H_A_m and M_A_m must have the same shape (n,), n >= 2; got "
                         f"{H.shape} and {Mt.shape}")
    if np.any(np.diff(H) <= 0) or H[0] < 0 or np.any(Mt < 0):
        raise InputError("H_A_m must be strictly increasing and >= 0 [A/m], M_A_m >= 0 [A/m]")

    def M(H_query):
        h = np.asarray(H_query, float)
        if np.any(h > H[-1] * (1 + 1e-12)) or np.any(h < H[0] * (1 - 1e-12)):
            raise InputError(f"field {h.min():g} .. {h.max():g} A/m outside the table's range "
                             f"[{H[0]:g}, {H[-1]:g}] A/m (no extrapolation)")
        return np.interp(h, H, Mt)
    return M


def _call_M(M_of_H, H):
    M = np.asarray(M_of_H(H), dtype=float)
    if M.shape != H.shape:
        raise InputError(f"M_of_H must return an array shaped like H {H.shape}, got {M.shape}")
    check_finite("M_of_H(H)", M, "A/m")
    if np.any(M < 0):
        raise InputError(f"M_of_H must return magnetization along H, >= 0 A/m; got "
                         f"{M.min():g} A/m")
    return M


def _internal_field(M_of_H, Ha, N, n_iter=200):
    """Solve ``h + N M(h) = Ha`` per point for the internal field ``h`` in ``[0, Ha]`` [A/m].

    ``g(h) = h + N M(h) - Ha`` has ``g(0) <= 0 <= g(Ha) = N M(Ha)``. A bracketing secant step
    (regula falsi with the Illinois modification: the end kept twice in a row has its ``g``
    halved; Dowell and Jarratt, BIT 11, 1971) replaced by bisection when it leaves the bracket
    or when the bracket has not halved in two steps, and kept ``2 eps Ha`` inside the bracket,
    so it never needs more steps than twice bisection's, and about 5-10 on a smooth or piecewise-linear (table) ``M``, where bisection
    took 50. Ends when the bracket is narrower than ``4 eps Ha`` or ``g`` is exactly 0;
    returns the root found, else the bracket's midpoint."""
    if N == 0.0:
        return Ha.copy()
    lo, hi = np.zeros_like(Ha), Ha.copy()
    glo = N * _call_M(M_of_H, lo) - Ha
    if np.any(glo > 0):
        raise InputError("M_of_H(0) must be 0 A/m (no remanence) when demag_factor > 0")
    ghi = N * _call_M(M_of_H, hi)
    tol = 4 * np.finfo(float).eps * np.maximum(Ha, 1e-300)
    root = np.where(glo == 0, lo, np.where(ghi == 0, hi, np.nan))
    kept = np.zeros(Ha.shape, dtype=np.int8)        # end kept in the last step: -1 lo, +1 hi
    ref = hi - lo                                   # the bracket's width two steps back
    for it in range(n_iter):
        act = np.isnan(root) & (hi - lo > tol)
        if not act.any():
            break
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            x = lo - glo * ((hi - lo) / (ghi - glo))
        bisect = ~np.isfinite(x)
        if it % 2 == 1:
            bisect |= (hi - lo) > 0.5 * ref
            ref = hi - lo
        # at least tol/2 inside the bracket: a secant point on the root's round-off lands on
        # an end, and the next step then closes the bracket from the other side
        x = np.where(bisect | ~act, 0.5 * (lo + hi), np.clip(x, lo + 0.5 * tol, hi - 0.5 * tol))
        g = x + N * _call_M(M_of_H, x) - Ha
        below, above = act & (g < 0), act & (g > 0)
        root = np.where(act & (g == 0), x, root)
        ghi = np.where(below & (kept == 1), 0.5 * ghi, ghi)
        glo = np.where(above & (kept == -1), 0.5 * glo, glo)
        lo, glo = np.where(below, x, lo), np.where(below, g, glo)
        hi, ghi = np.where(above, x, hi), np.where(above, g, ghi)
        kept = np.where(below, 1, np.where(above, -1, kept)).astype(np.int8)
    return np.where(np.isnan(root), 0.5 * (lo + hi), root)


@dataclass(frozen=True, eq=False)
class StripBodyForce:
    """Magnetic body force along a strip, averaged over its cross-section.

    Arrays are indexed by the ``n`` stations ``x_m`` along the strip and (where present) the
    ``c`` cross-section quadrature points.

    x_m : (n,) stations from the clamp [m];
    points_m : (n, c, 3) evaluation points [m]; weights : (c,) cross-section weights (sum 1);
    B_T : (n, c, 3) applied flux density [T]; grad_absB_T_per_m : (n, c, 3) [T/m];
    H_applied_A_m, H_internal_A_m, M_A_m : (n, c) field magnitudes and magnetization [A/m];
    f_points_N_m3 : (n, c, 3) body force at the points [N/m^3];
    f_N_m3 : (n, 3) cross-section mean of the body force [N/m^3];
    width_m, thickness_m : the strip's cross-section [m]; demag_factor : N used [-].
    """

    x_m: np.ndarray
    points_m: np.ndarray
    weights: np.ndarray
    B_T: np.ndarray
    grad_absB_T_per_m: np.ndarray
    H_applied_A_m: np.ndarray
    H_internal_A_m: np.ndarray
    M_A_m: np.ndarray
    f_points_N_m3: np.ndarray
    f_N_m3: np.ndarray
    width_m: float
    thickness_m: float
    demag_factor: float

    @property
    def transverse_N_m3(self) -> np.ndarray:
        """Body force along ``-z`` (the cantilever's load direction), shape (n,) [N/m^3]."""
        return -self.f_N_m3[:, 2]

    @property
    def total_force_N(self) -> np.ndarray:
        """Net force on the strip ``w t int_0^L f dx`` (Simpson), shape (3,) [N]."""
        return self.width_m * self.thickness_m * simpson(self.f_N_m3, x=self.x_m, axis=0)

    def profile(self) -> BodyForceProfile:
        """The transverse force as a profile for the macro solvers (linear between stations)."""
        return BodyForceProfile(self.x_m, self.transverse_N_m3)


def body_force_along_strip(source, strip_geometry: Strip, M_of_H, n_points: int = 101, *,
                           demag_factor: float = 0.0, n_cross: int = 3) -> StripBodyForce:
    """Body force density ``f = mu0 M_eff(H_in) grad |H_a|`` along the strip.

    Parameters
    ----------
    source : PermanentMagnet or Coil -- placed in the strip's frame, outside the strip
    strip_geometry : Strip -- the strip ``[0, L] x [0, w] x [0, t]`` [m]
    M_of_H : callable -- ``M_eff(H)`` [A/m] along the field for ``H`` [A/m] (ndarray in, same
        shape out, >= 0), e.g. :func:`linear_magnetization` or :func:`tabulated_magnetization`
    n_points : int -- stations along the length, equally spaced from 0 to L, >= 3
    demag_factor : float -- the specimen's demagnetizing factor for the field direction [-], in
        [0, 1] (e.g. :func:`micro.demag.prism_demag_factors`); ``H_in = |H_a| - N M``
    n_cross : int -- Gauss-Legendre points per cross-section direction (y and z) over which
        the force is averaged; 1 is the centreline

    Returns
    -------
    StripBodyForce -- ``f_N_m3`` (n, 3), ``transverse_N_m3`` (n,), ``total_force_N`` (3,),
    ``profile()`` for :func:`homogenize.macro.cantilever.solve_cantilever`

    Raises
    ------
    InputError -- the source overlaps the strip (checked on 25^3-point grids of both bodies,
        so an overlap thinner than 1/24 of both bodies' extents may pass; a coil is its winding,
        a strip inside its bore is accepted); bad parameters; ``M_of_H`` misbehaves
    """
    if not isinstance(strip_geometry, Strip):
        raise InputError(f"strip_geometry must be a Strip, got {type(strip_geometry).__name__}")
    if not float(n_points).is_integer() or int(n_points) < 3:
        raise InputError(f"n_points must be an integer >= 3, got {n_points!r}")
    if not float(n_cross).is_integer() or int(n_cross) < 1:
        raise InputError(f"n_cross must be an integer >= 1, got {n_cross!r}")
    N = check_range("demag_factor", demag_factor, 0.0, 1.0, "")
    if not callable(M_of_H):
        raise InputError("M_of_H must be a callable M(H) [A/m]")
    n, c1 = int(n_points), int(n_cross)
    L, w, t = strip_geometry.length_m, strip_geometry.width_m, strip_geometry.thickness_m
    _check_overlap(source, strip_geometry)
    x = np.linspace(0.0, L, n)
    gx, gw = np.polynomial.legendre.leggauss(c1)
    ys, zs = 0.5 * w * (1 + gx), 0.5 * t * (1 + gx)
    Y, Z = np.meshgrid(ys, zs, indexing="ij")
    weights = (np.outer(gw, gw) / 4.0).ravel()
    cross = np.column_stack([Y.ravel(), Z.ravel()])            # (c, 2)
    pts = np.empty((n, cross.shape[0], 3))
    pts[..., 0] = x[:, None]
    pts[..., 1:] = cross[None, :, :]
    B, grad = sample_field(source, pts.reshape(-1, 3))
    B = B.reshape(pts.shape)
    grad = grad.reshape(pts.shape)
    Ha = np.linalg.norm(B, axis=2) / MU0                       # in air: H = B / mu0
    Hin = _internal_field(M_of_H, Ha.ravel(), N).reshape(Ha.shape)
    M = _call_M(M_of_H, Hin)
    f_pts = M[..., None] * grad                                # mu0 M grad|H_a| = M grad|B_a|
    f = np.einsum("c,nci->ni", weights, f_pts)
    arrays = dict(x_m=x, points_m=pts, weights=weights, B_T=B, grad_absB_T_per_m=grad,
                  H_applied_A_m=Ha, H_internal_A_m=Hin, M_A_m=M, f_points_N_m3=f_pts,
                  f_N_m3=f)
    for a in arrays.values():
        a.flags.writeable = False
    return StripBodyForce(**arrays, width_m=w, thickness_m=t, demag_factor=N)
