"""Particle populations and their periodic placement: the RVE generator.

Three steps, each a small immutable object or pure function:

1. **Size distribution** of the *outer* particle radius: :class:`LogNormal` (truncated to
   ``[r_min, r_max]``, given by its median or by the mean of the truncated distribution),
   :class:`Histogram` (a measured histogram read from CSV) or :class:`Monodisperse`.
2. **Composition** :class:`CoreShell`: an Fe core and an Fe3O4 shell of thickness ``shell_m``
   give every particle its core radius, mass and saturation moment.
3. **Placement** in a periodic cube by random sequential addition (RSA) of rigid *bodies*
   (single particles, compact clusters or chains), largest first, with a minimum surface gap,
   using numba cell lists (O(N)). The box edge is chosen so that the drawn particles fill the
   requested volume fraction exactly; the size distribution is never adjusted. Beyond the
   reach of RSA, dispersed particles are packed by grow-and-relax compression.

The entry point is :func:`generate_rve`. :func:`describe` summarises an RVE (counts, volume
fraction, size, gap and cluster statistics).

Units: SI throughout (m, kg, A m^2, A m^2/kg).
"""
from __future__ import annotations

import csv
import math
import sys
from dataclasses import dataclass, fields
from pathlib import Path

import numpy as np
from scipy import special

from micro import _kernels as K
from micro.common.files import open_regular
from micro.common.validate import (InputError, check_choice, check_header, check_positive, check_range,
                        check_regular_file)
from micro.materials import FE, FE3O4, SEED
from micro.box import PeriodicBox
from micro.rve import RVE
from scipy.optimize import brentq
from scipy.spatial.transform import Rotation
from scipy.spatial.distance import pdist
from micro.common.progress import progress_bar

__all__ = ["ParticleConfig", "place", "LogNormal", "Histogram", "Monodisperse", "CoreShell", "default_distribution",
           "generate_rve", "describe", "cluster_packing_density", "pair_correlation",
           "min_surface_gap_m", "pair_distances", "cluster_members", "chain_axis",
           "chain_kappa", "chain_order_parameter", "ARRANGEMENTS", "PLACEMENTS",
           "FE_DENSITY_KG_M3", "FE_SIGMA_AM2_KG", "FE3O4_DENSITY_KG_M3", "FE3O4_SIGMA_AM2_KG",
           "SEED_SIGMA_AM2_KG"]

ARRANGEMENTS = ("dispersed", "clusters", "chains")
PLACEMENTS = ("auto", "rsa", "compress")
#: Upper bound accepted for phi (random close packing of monodisperse spheres is 0.64); whether
#: a given phi is reached depends on the distribution, arrangement and gap, and a jam is
#: reported with the phi actually reached.
PHI_MAX = 0.6

# Material constants: taken from micro.materials (their sources are there), under the names
# this module has always exported.
FE_DENSITY_KG_M3 = FE.density_kg_m3
FE_SIGMA_AM2_KG = FE.sigma_s_Am2_kg
FE3O4_DENSITY_KG_M3 = FE3O4.density_kg_m3
FE3O4_SIGMA_AM2_KG = FE3O4.sigma_s_Am2_kg
#: Specific saturation moment of the NANOFER powder used by the seed paper [A m^2/kg].
SEED_SIGMA_AM2_KG = SEED.sigma_s_Am2_kg


# =============================================================================================
# Size distributions of the outer radius
# =============================================================================================

class _Distribution:
    """Common interface: ``sample(n, rng)``, ``cdf(r)``, ``raw_moment(k)``, bounds."""

    r_min_m: float
    r_max_m: float

    def sample(self, n: int, rng: np.random.Generator) -> np.ndarray:
        """Draw ``n`` radii [m] by inverse transform sampling (one uniform per radius)."""
        return self.ppf(rng.random(n))

    def mean_volume_m3(self) -> float:
        """Expected outer particle volume [m^3]."""
        return 4.0 / 3.0 * math.pi * self.raw_moment(3)

    def core_shell_moments(self, shell_m: float) -> tuple[float, float]:
        """E[r_core^3] and E[r^3 - r_core^3] [m^3] for a shell of thickness ``shell_m``."""
        t = shell_m
        m1, m2, m3 = (self.raw_moment(k) for k in (1, 2, 3))
        core3 = m3 - 3 * t * m2 + 3 * t * t * m1 - t ** 3
        return core3, m3 - core3


def _lognormal_partial(k, mu, sigma, a, b):
    """Integral of r^k over the lognormal(mu, sigma) density on [a, b]."""
    za = (math.log(a) - mu - k * sigma ** 2) / sigma
    zb = (math.log(b) - mu - k * sigma ** 2) / sigma
    return math.exp(k * mu + 0.5 * k * k * sigma ** 2) * (special.ndtr(zb) - special.ndtr(za))


@dataclass(frozen=True)
class LogNormal(_Distribution):
    """Lognormal radius distribution truncated to ``[r_min_m, r_max_m]``.

    Parameters
    ----------
    median_m : float
        Median of the parent (untruncated) lognormal, exp(mu) [m].
    gsd : float
        Geometric standard deviation exp(sigma) [1], > 1.
    r_min_m, r_max_m : float
        Truncation bounds [m].

    Use :meth:`from_mean` to specify the mean of the *truncated* distribution instead.
    """

    median_m: float
    gsd: float
    r_min_m: float
    r_max_m: float

    def __post_init__(self):
        check_positive("median radius", self.median_m, "m")
        check_range("gsd (geometric standard deviation)", self.gsd, 1.0, 10.0, "", lo_open=True)
        _check_bounds(self.r_min_m, self.r_max_m)
        if self._mass() < 1e-12:
            raise InputError(f"the lognormal (median {self.median_m:g} m, gsd {self.gsd:g}) has "
                             f"no probability in [{self.r_min_m:g}, {self.r_max_m:g}] m")

    @classmethod
    def from_mean(cls, mean_m: float, gsd: float, r_min_m: float, r_max_m: float) -> "LogNormal":
        """The truncated lognormal whose mean (after truncation) is ``mean_m`` [m]."""

        check_positive("mean radius", mean_m, "m")
        check_range("gsd (geometric standard deviation)", gsd, 1.0, 10.0, "", lo_open=True)
        _check_bounds(r_min_m, r_max_m)
        if not (r_min_m < mean_m < r_max_m):
            raise InputError(f"mean radius must lie strictly inside [r_min, r_max] = "
                             f"[{r_min_m:g}, {r_max_m:g}] m, got {mean_m:g} m")
        s = math.log(gsd)

        def excess(mu):
            z = _lognormal_partial(0, mu, s, r_min_m, r_max_m)
            return _lognormal_partial(1, mu, s, r_min_m, r_max_m) / z - mean_m if z > 0 else (
                r_max_m - mean_m if mu > math.log(r_max_m) else r_min_m - mean_m)

        # The truncated mean rises monotonically from r_min to r_max as the median moves
        # through a wide bracket around the interval.
        lo, hi = math.log(r_min_m) - 8 * s, math.log(r_max_m) + 8 * s
        try:
            mu = brentq(excess, lo, hi, xtol=1e-14, rtol=1e-14, maxiter=200)
        except ValueError:
            raise InputError(f"no lognormal of gsd {gsd:g} truncated to [{r_min_m:g}, "
                             f"{r_max_m:g}] m has mean {mean_m:g} m; move the mean away from "
                             f"the bounds or widen the distribution") from None
        return cls(median_m=math.exp(mu), gsd=gsd, r_min_m=r_min_m, r_max_m=r_max_m)

    @property
    def _mu(self):
        return math.log(self.median_m)

    @property
    def _sigma(self):
        return math.log(self.gsd)

    def _mass(self):
        return _lognormal_partial(0, self._mu, self._sigma, self.r_min_m, self.r_max_m)

    def _z(self, r):
        return (np.log(r) - self._mu) / self._sigma

    def cdf(self, r):
        """Cumulative distribution of the truncated lognormal at ``r`` [m]."""
        r = np.clip(np.asarray(r, dtype=float), self.r_min_m, self.r_max_m)
        fa = special.ndtr(self._z(self.r_min_m))
        return (special.ndtr(self._z(r)) - fa) / self._mass()

    def ppf(self, u):
        """Inverse of :meth:`cdf` for ``u`` in [0, 1]."""
        fa = special.ndtr(self._z(self.r_min_m))
        r = np.exp(self._mu + self._sigma * special.ndtri(fa + np.asarray(u) * self._mass()))
        return np.clip(r, self.r_min_m, self.r_max_m)

    def raw_moment(self, k: int) -> float:
        """E[r^k] of the truncated distribution [m^k]."""
        return _lognormal_partial(k, self._mu, self._sigma, self.r_min_m,
                                  self.r_max_m) / self._mass()

    def params(self) -> dict:
        return {"kind": "lognormal", "median_m": self.median_m, "gsd": self.gsd,
                "r_min_m": self.r_min_m, "r_max_m": self.r_max_m,
                "mean_m": self.raw_moment(1)}


def _check_bounds(r_min_m, r_max_m):
    check_positive("r_min", r_min_m, "m")
    check_positive("r_max", r_max_m, "m")
    if r_min_m > r_max_m:
        raise InputError(f"r_min must be <= r_max, got r_min = {r_min_m:g} m > "
                         f"r_max = {r_max_m:g} m")


def default_distribution() -> LogNormal:
    """The seed paper's powder: mean radius 25 nm within [10, 50] nm; gsd 1.4 (assumed).

    The seed paper gives only the range and the Scherrer mean; the geometric standard deviation
    1.4 puts the 2.5 % and 97.5 % quantiles of the parent lognormal near the stated bounds.
    """
    return LogNormal.from_mean(25e-9, 1.4, 10e-9, 50e-9)


@dataclass(frozen=True)
class Monodisperse(_Distribution):
    """Every particle has radius ``radius_m`` [m]."""

    radius_m: float

    def __post_init__(self):
        check_positive("radius", self.radius_m, "m")

    @property
    def r_min_m(self):
        return self.radius_m

    @property
    def r_max_m(self):
        return self.radius_m

    def cdf(self, r):
        return (np.asarray(r, dtype=float) >= self.radius_m).astype(float)

    def ppf(self, u):
        return np.full(np.shape(u), self.radius_m)

    def raw_moment(self, k: int) -> float:
        return self.radius_m ** k

    def params(self) -> dict:
        return {"kind": "monodisperse", "radius_m": self.radius_m}


@dataclass(frozen=True)
class Histogram(_Distribution):
    """A measured radius histogram: number density uniform within each bin.

    Parameters
    ----------
    edges_m : tuple of float, length B + 1
        Increasing bin edges [m].
    weights : tuple of float, length B
        Number fraction in each bin (normalised here).
    source : str
        Where the data came from (file name), kept in the RVE parameters.
    """

    edges_m: tuple
    weights: tuple
    source: str = ""

    def __post_init__(self):
        e = np.asarray(self.edges_m, dtype=float)
        w = np.asarray(self.weights, dtype=float)
        if e.ndim != 1 or e.size < 2 or w.shape != (e.size - 1,):
            raise InputError("histogram needs B + 1 edges and B weights")
        if not np.all(np.isfinite(e)) or e[0] <= 0 or np.any(np.diff(e) <= 0):
            raise InputError("histogram edges must be finite, > 0 m and strictly increasing")
        if not np.all(np.isfinite(w)) or np.any(w < 0) or w.sum() <= 0:
            raise InputError("histogram weights must be finite, >= 0 and not all zero")
        object.__setattr__(self, "edges_m", tuple(float(x) for x in e))
        object.__setattr__(self, "weights", tuple(float(x) for x in w / w.sum()))

    @classmethod
    def from_csv(cls, path) -> "Histogram":
        """Read a CSV with header ``radius_m`` and ``count`` (number) or ``weight`` (mass).

        Each row is a bin centre and its count; bin edges lie halfway between neighbouring
        centres (half a spacing beyond the end rows). A ``weight`` column is a mass (volume)
        fraction and is converted to number fractions by dividing by radius^3. Rows with
        ``#`` in the first column are comments.
        """
        path = Path(path)
        check_regular_file(path, f"radius histogram file {path}", 64 * 2 ** 20)
        try:
            with open_regular(path, "r", newline="", encoding="utf-8") as fh:
                rows = [r for r in csv.reader(fh) if r and not r[0].lstrip().startswith("#")]
        except (OSError, UnicodeDecodeError, csv.Error) as exc:
            raise InputError(f"radius histogram file {path}: cannot be read ({exc})") from None
        if not rows:
            raise InputError(f"{path}: empty file, expected a header 'radius_m,count'")
        # a count (number) and a weight (mass) column both given: which one is meant is not
        # said, and they give different distributions
        header = check_header(f"{path}, row 1", rows[0], required=("radius_m",),
                              one_of=("count", "weight"))
        wcol = "count" if "count" in header else "weight"
        ir, iw = header.index("radius_m"), header.index(wcol)
        radii, weights = [], []
        for lineno, row in enumerate(rows[1:], start=2):
            vals = []
            for col, idx in (("radius_m", ir), (wcol, iw)):
                try:
                    v = float(row[idx])
                except (IndexError, ValueError):
                    raise InputError(f"{path}, row {lineno}, column {col}: not a number "
                                     f"({row[idx] if idx < len(row) else 'missing'!r})") from None
                if not math.isfinite(v):
                    raise InputError(f"{path}, row {lineno}, column {col}: not finite")
                vals.append(v)
            if vals[0] <= 0 or vals[0] > 1e-3:
                raise InputError(f"{path}, row {lineno}, column radius_m: must be in (0, 1e-3] m "
                                 f"(SI metres), got {vals[0]:g}")
            if vals[1] < 0:
                raise InputError(f"{path}, row {lineno}, column {wcol}: must be >= 0, "
                                 f"got {vals[1]:g}")
            if radii and vals[0] <= radii[-1]:
                raise InputError(f"{path}, row {lineno}, column radius_m: radii must increase")
            radii.append(vals[0])
            weights.append(vals[1])
        if not radii or sum(weights) <= 0:
            raise InputError(f"{path}: no data rows with a positive {wcol}")
        r = np.array(radii)
        w = np.array(weights)
        if wcol == "weight":
            w = w / r ** 3
        if r.size == 1:
            edges = np.array([r[0] * (1 - 1e-9), r[0] * (1 + 1e-9)])
        else:
            mid = 0.5 * (r[1:] + r[:-1])
            edges = np.concatenate([[r[0] - (mid[0] - r[0])], mid, [r[-1] + (r[-1] - mid[-1])]])
            if edges[0] <= 0:
                raise InputError(f"{path}, row 2, column radius_m: the first bin would reach "
                                 f"radius <= 0; add a smaller first radius")
        return cls(edges_m=tuple(edges), weights=tuple(w), source=str(path))

    @property
    def r_min_m(self):
        w = np.asarray(self.weights)
        return self.edges_m[int(np.flatnonzero(w > 0)[0])]

    @property
    def r_max_m(self):
        w = np.asarray(self.weights)
        return self.edges_m[int(np.flatnonzero(w > 0)[-1]) + 1]

    def _cum(self):
        return np.concatenate([[0.0], np.cumsum(self.weights)])

    def cdf(self, r):
        return np.interp(np.asarray(r, dtype=float), self.edges_m, self._cum())

    def ppf(self, u):
        cum = self._cum()
        u = np.asarray(u, dtype=float)
        # Empty bins make cum flat: search for the bin, then interpolate inside it.
        b = np.clip(np.searchsorted(cum, u, side="right") - 1, 0, len(self.weights) - 1)
        w = np.asarray(self.weights)[b]
        e = np.asarray(self.edges_m)
        frac = np.where(w > 0, (u - cum[b]) / np.where(w > 0, w, 1.0), 0.0)
        return e[b] + np.clip(frac, 0.0, 1.0) * (e[b + 1] - e[b])

    def raw_moment(self, k: int) -> float:
        e = np.asarray(self.edges_m)
        w = np.asarray(self.weights)
        return float(np.sum(w * (e[1:] ** (k + 1) - e[:-1] ** (k + 1)) / ((k + 1) * np.diff(e))))

    def params(self) -> dict:
        return {"kind": "histogram", "source": self.source, "edges_m": list(self.edges_m),
                "weights": list(self.weights)}


# =============================================================================================
# Core-shell composition
# =============================================================================================

@dataclass(frozen=True)
class CoreShell:
    """Fe core + Fe3O4 shell of uniform thickness: per-particle core radius, mass and moment.

    Parameters
    ----------
    shell_m : float
        Shell thickness t [m], >= 0 and smaller than the smallest particle radius. With
        ``t = 0`` every particle is homogeneous with the seed paper's 7870 kg/m^3 and
        178 A m^2/kg (unless ``core_sigma_Am2_kg`` is given).
    core_density_kg_m3, core_sigma_Am2_kg : float
        Density [kg/m^3] and specific saturation moment [A m^2/kg] of the core. Default
        Fe: 7870 kg/m^3 and 218 A m^2/kg (see ``FE_*`` for sources); 178 A m^2/kg if t = 0.
    shell_density_kg_m3, shell_sigma_Am2_kg : float
        Same for the shell. Default Fe3O4: 5170 kg/m^3, 92 A m^2/kg (see ``FE3O4_*``).
    calibrate_sigma_Am2_kg : float or None
        A measured mass-averaged specific moment of the powder [A m^2/kg] (datasheet value,
        e.g. 178). If given, the core's specific moment is chosen so that the *population*
        (the size distribution, not the finite sample in one RVE) has this mass average;
        every RVE drawn from the same powder then has the same core moment.
    """

    shell_m: float = 0.0
    core_density_kg_m3: float = FE_DENSITY_KG_M3
    core_sigma_Am2_kg: float | None = None
    shell_density_kg_m3: float = FE3O4_DENSITY_KG_M3
    shell_sigma_Am2_kg: float = FE3O4_SIGMA_AM2_KG
    calibrate_sigma_Am2_kg: float | None = None

    def __post_init__(self):
        check_positive("shell thickness", self.shell_m, "m", allow_zero=True)
        check_positive("core density", self.core_density_kg_m3, "kg/m^3")
        check_positive("shell density", self.shell_density_kg_m3, "kg/m^3")
        check_positive("shell specific moment", self.shell_sigma_Am2_kg, "A m^2/kg",
                       allow_zero=True)
        if self.core_sigma_Am2_kg is not None:
            check_positive("core specific moment", self.core_sigma_Am2_kg, "A m^2/kg",
                           allow_zero=True)
        if self.calibrate_sigma_Am2_kg is not None:
            check_positive("calibration specific moment", self.calibrate_sigma_Am2_kg,
                           "A m^2/kg")

    def nominal_core_sigma(self) -> float:
        """Core specific moment before calibration [A m^2/kg]."""
        if self.core_sigma_Am2_kg is not None:
            return float(self.core_sigma_Am2_kg)
        return SEED_SIGMA_AM2_KG if self.shell_m == 0 else FE_SIGMA_AM2_KG

    def check_against(self, distribution) -> None:
        """Refuse a shell as thick as the smallest particle radius of ``distribution``."""
        if self.shell_m >= distribution.r_min_m:
            raise InputError(f"shell thickness {self.shell_m:g} m must be smaller than the "
                             f"smallest particle radius {distribution.r_min_m:g} m")

    def core_sigma(self, distribution) -> float:
        """Core specific moment [A m^2/kg], calibrated against ``distribution`` if asked."""
        if self.calibrate_sigma_Am2_kg is None:
            return self.nominal_core_sigma()
        self.check_against(distribution)
        core3, shell3 = distribution.core_shell_moments(self.shell_m)
        m_core = self.core_density_kg_m3 * core3
        m_shell = self.shell_density_kg_m3 * shell3
        target = float(self.calibrate_sigma_Am2_kg)
        sigma = (target * (m_core + m_shell) - self.shell_sigma_Am2_kg * m_shell) / m_core
        if sigma < 0:
            reach = self.shell_sigma_Am2_kg * m_shell / (m_core + m_shell)
            raise InputError(f"calibration specific moment {target:g} A m^2/kg is below what the "
                             f"shell alone carries ({reach:.4g} A m^2/kg) for shell thickness "
                             f"{self.shell_m:g} m; lower the shell moment or thickness")
        return float(sigma)

    def apply(self, radii_m: np.ndarray, core_sigma_Am2_kg: float):
        """Core radii [m], masses [kg] and saturation moments [A m^2] of particles (N,)."""
        r = np.asarray(radii_m, dtype=float)
        rc = r - self.shell_m
        if np.any(rc <= 0):
            raise InputError(f"shell thickness {self.shell_m:g} m must be smaller than the "
                             f"smallest particle radius {r.min():g} m")
        vc = 4.0 / 3.0 * np.pi * rc ** 3
        vs = 4.0 / 3.0 * np.pi * r ** 3 - vc
        mass_c = self.core_density_kg_m3 * vc
        mass_s = self.shell_density_kg_m3 * vs
        m_sat = core_sigma_Am2_kg * mass_c + self.shell_sigma_Am2_kg * mass_s
        return rc, mass_c + mass_s, m_sat

    def params(self, core_sigma_used: float) -> dict:
        return {"shell_m": self.shell_m, "core_density_kg_m3": self.core_density_kg_m3,
                "core_sigma_Am2_kg": core_sigma_used,
                "shell_density_kg_m3": self.shell_density_kg_m3,
                "shell_sigma_Am2_kg": self.shell_sigma_Am2_kg,
                "calibrate_sigma_Am2_kg": self.calibrate_sigma_Am2_kg}


# =============================================================================================
# Bodies: isolated particles, compact clusters, chains
# =============================================================================================

def cluster_packing_density(offsets_m: np.ndarray, radii_m: np.ndarray) -> float:
    """Packing density of a cluster: solid volume / volume of its gyration-equivalent sphere.

    The gyration radius of the solid, R_g^2 = sum v_i (|x_i - c|^2 + 3/5 r_i^2) / sum v_i
    (c the volume-weighted centroid), equals that of a uniform ball of radius
    R = sqrt(5/3) R_g; the density is sum v_i / (4/3 pi R^3). It is 1 for a single sphere
    and tends to the bulk packing fraction for a large cluster packed uniformly in a ball.

    Parameters
    ----------
    offsets_m : ndarray, shape (k, 3) -- member centres (unwrapped) [m]
    radii_m : ndarray, shape (k,) -- member radii [m]
    """
    x = np.asarray(offsets_m, dtype=float)
    r = np.asarray(radii_m, dtype=float)
    v = r ** 3
    c = (v[:, None] * x).sum(0) / v.sum()
    rg2 = np.sum(v * (np.sum((x - c) ** 2, axis=1) + 0.6 * r ** 2)) / v.sum()
    return float(v.sum() / (rg2 * 5.0 / 3.0) ** 1.5)


def _grow_cluster(r, gap, rng, n_dir=64):
    """A dense random cluster: spheres added largest first, each at the deepest surface site.

    For each new sphere, ``n_dir`` random rays leave the current volume-weighted centroid; along
    each ray the sphere is put just outside every member it would overlap (the largest root of
    |c + t u - x_j| = r + r_j + gap), and the ray with the smallest such t wins. Every sphere
    is placed at least ``gap`` from all earlier ones, so the cluster is overlap-free by
    construction (the factor 1 + 1e-9 keeps rounding on the safe side).
    """
    k = r.size
    order = np.argsort(-r, kind="stable")
    x = np.zeros((k, 3))
    v = r ** 3
    for m in range(1, k):
        i = order[m]
        placed = order[:m]
        c = (v[placed, None] * x[placed]).sum(0) / v[placed].sum()
        u = rng.normal(size=(n_dir, 3))
        u /= np.linalg.norm(u, axis=1)[:, None]
        w = x[placed] - c
        contact = r[i] + r[placed] + gap
        b = u @ w.T
        disc = b * b - (np.sum(w * w, axis=1) - contact * contact)[None, :]
        t = np.where(disc > 0, b + np.sqrt(np.maximum(disc, 0.0)), 0.0).max(axis=1)
        best = int(np.argmin(t))
        x[i] = c + t[best] * (1 + 1e-9) * u[best]
    return x


def _compact_cluster(r, density, gap, rng):
    """Centres (k, 3) relative to the volume-weighted centroid of a cluster of radii ``r`` whose
    :func:`cluster_packing_density` equals ``density``.

    A dense random cluster (:func:`_grow_cluster`, packing density about 0.55-0.65) is
    expanded uniformly about its centroid until its packing density is exactly ``density``;
    expansion only increases distances, so it never creates overlaps.
    """
    k = r.size
    x = _grow_cluster(r, gap, rng)
    v = r ** 3
    x = x - (v[:, None] * x).sum(0) / v.sum()
    d1 = cluster_packing_density(x, r)
    if d1 < density * (1 - 1e-9):
        raise InputError(f"cluster_density {density:g} is above what the cluster builder reaches "
                         f"for clusters of {k} particles (about {d1:.3f} with this gap); use a "
                         f"lower cluster density or larger clusters")
    # Solve R_g(s)^2 = (3/5) R_eq^2 for the uniform expansion factor s >= 1.
    req2 = (v.sum() / density) ** (2.0 / 3.0)
    spread = np.sum(v * np.sum(x * x, axis=1)) / v.sum()
    own = 0.6 * np.sum(v * r * r) / v.sum()
    s = math.sqrt(max(0.6 * req2 - own, 0.0) / spread) if spread > 0 else 1.0
    return x * max(s, 1.0)


def _random_rotation(rng):
    """A uniformly random rotation matrix (normalised Gaussian quaternion)."""

    q = rng.normal(size=4)
    return Rotation.from_quat(q / np.linalg.norm(q)).as_matrix()


def _chain_offsets(r, gap, direction):
    """Centres of touching (surface distance ``gap``) spheres along ``direction``, centroid 0."""
    # 1 + 1e-9: neighbours touch (at distance gap) without rounding ever making them overlap.
    s = np.concatenate([[0.0], np.cumsum((r[:-1] + r[1:] + gap) * (1 + 1e-9))])
    x = s[:, None] * direction[None, :]
    v = r ** 3
    return x - (v[:, None] * x).sum(0) / v.sum()


def _fisher_directions(direction, kappa, k, rng):
    """``k`` unit vectors from the Fisher (von Mises-Fisher) distribution about ``direction``
    with concentration ``kappa`` (density ~ exp(kappa cos theta)); exact inverse-CDF sampling
    of cos theta, uniform azimuth. ``kappa = inf`` returns ``direction`` itself."""
    if not np.isfinite(kappa):
        return np.tile(direction, (k, 1))
    u = rng.random(k)
    w = 1.0 + np.log(u + (1.0 - u) * np.exp(-2.0 * kappa)) / kappa
    w = np.clip(w, -1.0, 1.0)
    az = 2.0 * np.pi * rng.random(k)
    a = np.array([1.0, 0.0, 0.0]) if abs(direction[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = a - (a @ direction) * direction
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(direction, e1)
    s = np.sqrt(1.0 - w * w)
    return ((s * np.cos(az))[:, None] * e1 + (s * np.sin(az))[:, None] * e2
            + w[:, None] * direction)


def chain_kappa(spread_deg: float) -> float:
    """Fisher concentration for a chain-axis spread [deg]: kappa = 2 / spread^2 (spread in
    rad), so that the RMS angle to the mean direction is about ``spread_deg`` for small
    spreads; ``inf`` for 0 (perfect alignment)."""
    return math.inf if spread_deg == 0 else 2.0 / math.radians(spread_deg) ** 2


def chain_order_parameter(kappa: float) -> float:
    """Expected nematic order S = <(3 cos^2 theta - 1) / 2> of Fisher-distributed axes:
    S = 1 - 3 L(kappa) / kappa with the Langevin function L = coth(kappa) - 1 / kappa."""
    if not np.isfinite(kappa):
        return 1.0
    lang = 1.0 / math.tanh(kappa) - 1.0 / kappa
    return 1.0 - 3.0 * lang / kappa


def _chain_lengths(n_agg, mean_length, max_length, rng):
    """Chain lengths >= 2 from a geometric distribution of mean ``mean_length`` summing to n_agg.

    The most probable (Flory) distribution of linear aggregates, P(l) ~ (1 - p)^(l - 2),
    l >= 2, cut at ``max_length``; a last length of 1 (isolated particle) is dropped.
    """
    p = 1.0 / (mean_length - 1.0)
    lengths = []
    total = 0
    while total < n_agg:
        ell = min(1 + int(rng.geometric(p)), max_length, n_agg - total)
        lengths.append(ell)
        total += ell
    return [ell for ell in lengths if ell >= 2]


def _bodies(radii, box, rng, arrangement, gap, cluster_size, cluster_density, chain_length,
            direction, agglomerated_fraction, kappa=math.inf):
    """Split particles into rigid bodies.

    Returns (groups, singles): a list of (particle indices (k,), centre offsets (k, 3)) for the
    clusters or chains, and the indices of the isolated particles.
    """
    n = radii.size
    perm = rng.permutation(n)
    n_agg = int(round(agglomerated_fraction * n)) if arrangement != "dispersed" else 0
    groups = []
    if arrangement == "clusters" and n_agg >= 2:
        n_cl = max(1, int(round(n_agg / cluster_size)))
        for idx in np.array_split(perm[:n_agg], n_cl):
            if idx.size >= 2:
                x = _compact_cluster(radii[idx], cluster_density, gap, rng)
                groups.append((idx, x @ _random_rotation(rng).T))
    elif arrangement == "chains" and n_agg >= 2:
        # Chains must span less than half the box (periodic unwrapping); longer ones are cut.
        limit = 0.5 * box - 2.0 * radii.max() - gap
        start = 0
        for ell in _chain_lengths(n_agg, chain_length, n_agg, rng):
            idx = perm[start:start + ell]
            start += ell
            pieces, piece, span = [], [idx[0]], 0.0
            for j in idx[1:]:
                step = (radii[piece[-1]] + radii[j] + gap) * (1 + 1e-9)
                if span + step > limit:
                    pieces.append(piece)
                    piece, span = [j], 0.0
                else:
                    piece.append(j)
                    span += step
            pieces.append(piece)
            for piece in pieces:
                if len(piece) >= 2:
                    piece = np.asarray(piece)
                    axis = _fisher_directions(direction, kappa, 1, rng)[0]
                    groups.append((piece, _chain_offsets(radii[piece], gap, axis)))
    used = np.zeros(n, bool)
    for idx, _x in groups:
        used[idx] = True
    return groups, perm[~used[perm]]


def _span(x):
    """Largest distance between two centres of a body [m] (0 for a single particle)."""
    if len(x) < 2:
        return 0.0
    return float(pdist(x).max())


def _place_bodies(offsets, radii, body_start, box, gap, rng, max_attempts, kernel,
                  progress=False):
    """Run the RSA kernel on batches of uniform candidates drawn from ``rng``.

    ``kernel`` is :func:`micro._kernels.placement_rsa_bodies` or a reference with its
    signature. Returns (centers (N, 3), state, status) where state = [bodies placed, failed
    attempts on the next body, total attempts] and status is the kernel's (0 done, 2 jammed).
    The batch sizes depend only on the state, so the result is a function of the seed alone.
    """
    n = radii.size
    nbody = body_start.size - 1
    contact = 2.0 * radii.max() + gap
    ncell = max(1, int(box / contact))
    while ncell ** 3 > 8 * n + 27:     # more cells than that only costs memory
        ncell -= 1
    head = np.full(ncell ** 3, -1, dtype=np.int64)
    nxt = np.full(n, -1, dtype=np.int64)
    centers = np.zeros((n, 3))
    state = np.zeros(3, dtype=np.int64)
    bar = None
    if progress:
        bar = progress_bar(total=nbody, desc="placing", unit="body", file=sys.stderr)
    try:
        while True:
            batch = int(min(max(4096, 2 * (nbody - state[0])), 1 << 20))
            cand = rng.random((batch, 3)) * box
            before = int(state[0])
            status = kernel(offsets, radii, body_start, cand, gap, box, ncell, head, nxt,
                            centers, state, max_attempts)
            if bar is not None:
                bar.update(int(state[0]) - before)
            if status != 1:
                break
    finally:
        if bar is not None:
            bar.close()
    return centers, state, status


def _relax(x, radii, gap, box, iters, push_scale=1.01):
    """Remove overlaps by repeated pair pushes (cell lists); returns (clean, positions).

    Each overlapping pair is pushed to 1 % beyond contact (``push_scale``): the overshoot
    opens room around crowded particles, so that the Jacobi iteration converges in tens of
    steps instead of stalling near contact (measured: 0.55 monodisperse in 2 s instead of 80 s
    for 2000 spheres). Only true overlaps (distance < r_i + r_j + gap) are pushed or counted.
    """
    contact = 2.0 * radii.max() + gap
    ncell = max(1, int(box / (contact * (1 + 1e-9))))
    while ncell ** 3 > 8 * x.shape[0] + 27:
        ncell -= 1
    head = np.empty(ncell ** 3, dtype=np.int64)
    nxt = np.empty(x.shape[0], dtype=np.int64)
    disp = np.empty_like(x)
    x = np.ascontiguousarray(x)
    pbox = PeriodicBox(box)
    for _ in range(iters):
        K.placement_build_cells(x, box, ncell, head, nxt)
        if K.placement_relax_step(x, radii, gap, push_scale, box, ncell, head, nxt, disp) == 0:
            return True, x
        x = pbox.wrap(x + disp)
    return False, x


def _compress(radii, box, gap, rng, max_attempts, progress=False):
    """Grow-and-relax placement of single spheres beyond the reach of RSA.

    The spheres are first placed by RSA at volume fraction 0.25 in a larger box; the box is
    then shrunk in steps (positions scaled affinely) and the overlaps created by each step are
    removed by :func:`_relax`. The step shrinks when relaxation stalls; below a 1e-4 relative
    step the packing is declared jammed. Returns the centres in the box of edge ``box``.
    """
    n = radii.size
    phi_target = 4.0 / 3.0 * np.pi * np.sum(radii ** 3) / box ** 3
    phi0 = min(phi_target, 0.25)
    L = box * (phi_target / phi0) ** (1.0 / 3.0)
    x, state, status = _place_bodies(np.zeros((n, 3)), radii, np.arange(n + 1, dtype=np.int64),
                                     L, gap, rng, max_attempts, K.placement_rsa_bodies)
    if status != 0:
        raise InputError(f"could not place the particles at phi = {phi0:g} to start compression")
    step = 0.02
    L0 = L
    bar = None
    if progress and L0 > box:
        bar = progress_bar(total=100, desc="compressing", unit="%", file=sys.stderr)
    try:
        while L > box:
            L_new = max(box, L * (1.0 - step))
            ok, y = _relax(x * (L_new / L), radii, gap, L_new, iters=200)
            if ok:
                if bar is not None:
                    bar.n = int(100 * (L0 - L_new) / (L0 - box))
                    bar.refresh()
                x, L = y, L_new
                step = min(1.5 * step, 0.02)
            else:
                step *= 0.5
                if step < 1e-4:
                    reached = phi_target * (box / L) ** 3
                    raise InputError(f"compression jammed at phi = {reached:.4f} below the "
                                     f"requested phi = {phi_target:.4g}; this is the densest "
                                     f"packing reachable for this distribution and gap: lower "
                                     f"phi or gap_m")
    finally:
        if bar is not None:
            bar.close()
    return PeriodicBox(box).wrap(x * (box / L))


def generate_rve(phi, n, seed, *, distribution=None, composition=None, arrangement="dispersed",
                 gap_m=0.0, cluster_size=20, cluster_density=0.5, chain_length=5.0,
                 chain_direction=(0.0, 0.0, 1.0), chain_spread_deg=0.0,
                 agglomerated_fraction=1.0,
                 max_attempts=200_000, placement="auto", progress=False) -> RVE:
    """Draw ``n`` particles and place them in a periodic cube at volume fraction ``phi``.

    Parameters
    ----------
    phi : float
        Target particle volume fraction (outer volumes / box volume) [1], in (0, 0.6].
        Met to rounding: the box edge is L = (sum of particle volumes / phi)^(1/3).
    n : int
        Number of particles.
    seed : int or None
        Seed of the ``numpy.random.Generator``; same seed, same RVE.
    distribution : LogNormal, Histogram or Monodisperse, optional
        Outer-radius distribution; default :func:`default_distribution` (mean 25 nm in
        [10, 50] nm, gsd 1.4).
    composition : CoreShell, optional
        Core-shell composition; default homogeneous particles with the seed's 7870 kg/m^3 and
        178 A m^2/kg.
    arrangement : {"dispersed", "clusters", "chains"}
        Isolated particles, compact clusters or chains (the fraction
        ``agglomerated_fraction`` of the particles is agglomerated, the rest isolated).
    gap_m : float
        Minimum surface-to-surface distance between any two particles [m], >= 0 (also inside
        clusters and chains, whose neighbours sit exactly at this distance when touching).
    cluster_size : int
        Mean number of particles per cluster (>= 2); clusters differ in size by at most one.
    cluster_density : float
        Internal packing density of each cluster, see :func:`cluster_packing_density`, in
        (0, 0.6].
    chain_length : float
        Mean number of particles per chain (>= 2); lengths follow a geometric distribution,
        cut at half the box edge.
    chain_direction : sequence of 3 floats
        Mean chain axis (normalised here), e.g. the curing field direction.
    chain_spread_deg : float
        Misalignment of the chains [deg], in [0, 90]: each chain axis is drawn from a Fisher
        distribution about ``chain_direction`` with concentration 2 / spread^2 (RMS angle
        about ``chain_spread_deg``); 0 = all chains exactly along the direction.
    agglomerated_fraction : float
        Fraction of the particles in clusters or chains, in [0, 1].
    max_attempts : int
        Random positions tried for one body before the placement is declared jammed.
    placement : {"auto", "rsa", "compress"}
        "rsa": random sequential addition only (a jam is an error naming the phi reached);
        "compress": grow and relax (RSA at phi 0.25 in a larger box, then stepwise affine
        compression with overlap removal), reaching denser packings than RSA (monodisperse
        RSA saturates at 0.384) but only for ``arrangement="dispersed"``; "auto": RSA, and for
        dispersed particles compression if RSA jams.
    progress : bool
        Show a progress bar on stderr.

    Returns
    -------
    RVE
        Particles in placement order (largest body first).
    """
    phi = check_range("phi (volume fraction)", phi, 0.0, PHI_MAX, "", lo_open=True)
    if isinstance(n, bool) or not float(n).is_integer():
        raise InputError(f"n (number of particles) must be an integer, got {n!r}")
    n = int(check_range("n (number of particles)", n, 1, 50_000_000))
    if seed is not None and (isinstance(seed, bool) or not float(seed).is_integer() or seed < 0):
        raise InputError(f"seed must be a non-negative integer or None, got {seed!r}")
    dist = default_distribution() if distribution is None else distribution
    comp = CoreShell() if composition is None else composition
    check_choice("arrangement", arrangement, ARRANGEMENTS)
    gap = check_positive("gap", gap_m, "m", allow_zero=True)
    if isinstance(cluster_size, bool) or not float(cluster_size).is_integer():
        raise InputError(f"cluster_size must be an integer, got {cluster_size!r}")
    cluster_size = int(check_range("cluster_size (particles per cluster)", cluster_size, 2, 5000))
    cluster_density = check_range("cluster_density (internal packing density)", cluster_density,
                                  0.0, 0.6, "", lo_open=True)
    chain_length = check_range("chain_length (mean particles per chain)", chain_length, 2.0, 1e4)
    direction = np.asarray(_check_vector("chain_direction", chain_direction), float)
    if np.linalg.norm(direction) == 0:
        raise InputError("chain_direction must be a non-zero 3-vector")
    direction = direction / np.linalg.norm(direction)
    spread = check_range("chain_spread_deg", chain_spread_deg, 0.0, 90.0, "deg")
    agg = check_range("agglomerated_fraction", agglomerated_fraction, 0.0, 1.0)
    max_attempts = int(check_range("max_attempts", max_attempts, 1, 1e9))
    check_choice("placement", placement, PLACEMENTS)
    if placement == "compress" and arrangement != "dispersed":
        raise InputError(f"placement 'compress' works for arrangement 'dispersed' only, got "
                         f"{arrangement!r}; use placement 'rsa'")
    comp.check_against(dist)
    core_sigma = comp.core_sigma(dist)

    rng = np.random.default_rng(seed)
    radii = dist.sample(n, rng)
    box = float((4.0 / 3.0 * np.pi * np.sum(radii ** 3) / phi) ** (1.0 / 3.0))
    if box < 2.0 * (2.0 * radii.max() + gap):
        raise InputError(f"the box edge {box:.4g} m for n = {n} particles at phi = {phi:g} is less "
                         f"than twice the largest contact distance {2 * radii.max() + gap:.4g} m; "
                         f"use more particles")

    groups, singles = _bodies(radii, box, rng, arrangement, gap, cluster_size, cluster_density,
                              chain_length, direction, agg, chain_kappa(spread))
    span = max([_span(x) for _idx, x in groups], default=0.0)
    if span + 2.0 * radii.max() + gap > 0.5 * box:
        raise InputError(f"a cluster spanning {span + 2 * radii.max():.4g} m does not fit in half "
                         f"the box edge {box:.4g} m; use more particles (n) or smaller clusters")
    # Bodies: the groups, then the single particles; members listed body by body.
    n_groups = len(groups)
    member = np.concatenate([idx for idx, _x in groups] + [singles]).astype(np.int64)
    off = np.concatenate([x for _idx, x in groups] + [np.zeros((singles.size, 3))])
    sizes = np.concatenate([[idx.size for idx, _x in groups],
                            np.ones(singles.size)]).astype(np.int64)
    body_of = np.repeat(np.arange(sizes.size), sizes)
    extent = np.concatenate([[np.max(np.linalg.norm(x, axis=1) + radii[idx]) for idx, x in groups],
                             radii[singles]])
    order = np.argsort(-extent, kind="stable")          # largest body first
    rank = np.empty_like(order)
    rank[order] = np.arange(order.size)
    by_body = np.argsort(rank[body_of], kind="stable")
    member, off, body_of = member[by_body], off[by_body], body_of[by_body]
    body_start = np.concatenate([[0], np.cumsum(sizes[order])]).astype(np.int64)
    r_all = np.ascontiguousarray(radii[member])
    off = np.ascontiguousarray(off)
    method = "rsa"
    if placement == "compress":
        centers, status, method = _compress(r_all, box, gap, rng, max_attempts, progress), 0, \
            "compress"
    else:
        centers, state, status = _place_bodies(off, r_all, body_start, box, gap, rng,
                                               max_attempts, K.placement_rsa_bodies, progress)
    if status == 2:
        placed = int(body_start[state[0]])
        reached = float(np.sum(r_all[:placed] ** 3) * 4.0 / 3.0 * np.pi / box ** 3)
        if placement == "auto" and arrangement == "dispersed":
            centers, method = _compress(r_all, box, gap, rng, max_attempts, progress), "compress"
        else:
            raise InputError(
                f"random sequential addition jammed at phi = {reached:.4f} ({placed} of {n} "
                f"particles placed, {max_attempts} attempts for the next body) below the "
                f"requested phi = {phi:g}; this is the reachable limit for this distribution, "
                f"arrangement and gap: lower phi or gap_m" + (
                    "" if arrangement != "dispersed" else ", or use placement 'compress'"))
    # Cluster ids numbered in placement order; -1 for isolated particles.
    is_group = body_of < n_groups
    cluster_id = np.full(n, -1, dtype=np.int64)
    cluster_id[is_group] = rank[body_of[is_group]]
    cluster_id[is_group] = np.unique(cluster_id[is_group], return_inverse=True)[1]
    rc, mass, m_sat = comp.apply(r_all, core_sigma)
    params = {
        "phi": phi, "n": n, "distribution": dist.params(), "composition": comp.params(core_sigma),
        "arrangement": arrangement, "gap_m": gap, "cluster_size": cluster_size,
        "cluster_density": cluster_density, "chain_length": chain_length,
        "chain_direction": direction.tolist(), "chain_spread_deg": spread,
        "agglomerated_fraction": agg,
        "max_attempts": max_attempts, "placement": placement, "placement_used": method,
        "generator": "micro.particles.generate_rve (RSA with cell lists, largest body first; "
                     "grow-and-relax compression beyond the RSA limit)",
    }
    return RVE(box_m=box, centers_m=centers, radii_m=r_all, core_radii_m=rc, m_sat_Am2=m_sat,
               mass_kg=mass, cluster_id=cluster_id, seed=seed, params=params)




@dataclass(frozen=True)
class ParticleConfig:
    """Everything the placement stage needs (frozen; SI units). See :func:`generate_rve`.

    ``distribution`` None is the seed's powder (:func:`default_distribution`); ``composition``
    None is homogeneous particles with the seed's specific moment.
    """

    phi: float
    n: int
    seed: int = 0
    distribution: object = None
    composition: object = None
    arrangement: str = "dispersed"
    gap_m: float = 0.0
    cluster_size: int = 20
    cluster_density: float = 0.5
    chain_length: float = 5.0
    chain_direction: tuple = (0.0, 0.0, 1.0)
    chain_spread_deg: float = 0.0
    agglomerated_fraction: float = 1.0
    max_attempts: int = 200_000
    placement: str = "auto"

    def generator_kwargs(self) -> dict:
        """The keywords of :func:`generate_rve` beyond ``phi, n, seed``."""
        return {f.name: getattr(self, f.name) for f in fields(self)
                if f.name not in ("phi", "n", "seed")}


def place(config: ParticleConfig, progress: bool = False) -> RVE:
    """The placement stage: a periodic RVE drawn and placed as ``config`` says."""
    return generate_rve(config.phi, config.n, config.seed, progress=progress,
                        **config.generator_kwargs())


def _check_vector(name, value):
    try:
        v = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise InputError(f"{name} must be 3 numbers, got {value!r}") from None
    if v.shape != (3,) or not np.all(np.isfinite(v)):
        raise InputError(f"{name} must be 3 finite numbers, got {value!r}")
    return v


# =============================================================================================
# Statistics of an RVE
# =============================================================================================

def _unwrap(centers, box):
    """Unwrap a compact group of centres (extent < box/2) relative to its first member."""
    d = centers - centers[0]
    return centers[0] + PeriodicBox(box).minimum_image(d)


def pair_distances(rve: RVE, r_max_m: float):
    """All centre pairs whose minimum-image distance is below ``r_max_m``: (i, j, d [m]), with
    i < j, sorted by i then j (:meth:`micro.box.PeriodicBox.pairs_within`)."""

    if rve.n < 2:
        return np.zeros(0, int), np.zeros(0, int), np.zeros(0)
    return rve.box.pairs_within(rve.centers_m, r_max_m)


def min_surface_gap_m(rve: RVE) -> float:
    """Smallest surface-to-surface distance over all pairs, periodic images included [m].

    Pairs with centres farther apart than R have gaps above R - 2 r_max, so a neighbour search
    whose radius R doubles until the smallest gap found is below R - 2 r_max is exact; a
    particle's own images (at distance L) count too.
    """
    if rve.n == 0:
        return float("inf")
    own = rve.box_m - 2.0 * rve.radii_m.max()
    r2 = 2.0 * rve.radii_m.max()
    reach = 1.5 * r2
    all_pairs = math.sqrt(3.0) / 2.0 * rve.box_m * (1 + 1e-9)   # largest minimum-image distance
    while True:
        i, j, d = pair_distances(rve, min(reach, all_pairs))
        gap = float(np.min(d - rve.radii_m[i] - rve.radii_m[j])) if i.size else float("inf")
        if gap <= reach - r2 or reach >= all_pairs:
            return min(gap, own)
        reach *= 2.0


def pair_correlation(rve: RVE, r_edges_m) -> np.ndarray:
    """Radial distribution function g(r) of the centres on the bins ``r_edges_m`` [m].

    g = (pairs in a shell) / (pairs expected for an ideal gas of the same number density);
    periodic, r must stay below half the box edge.
    """
    edges = np.asarray(r_edges_m, dtype=float)
    if edges[-1] > 0.5 * rve.box_m:
        raise InputError(f"g(r) bins must end below half the box edge {0.5 * rve.box_m:g} m")
    _i, _j, d = pair_distances(rve, edges[-1])
    counts, _ = np.histogram(d, bins=edges)
    shell = 4.0 / 3.0 * np.pi * (edges[1:] ** 3 - edges[:-1] ** 3)
    return 2.0 * counts / (rve.n * rve.number_density_m3 * shell)


def cluster_members(rve: RVE) -> list[np.ndarray]:
    """Unwrapped member centres of every cluster/chain, one (k, 3) array per cluster id."""
    out = []
    for c in range(int(rve.cluster_id.max(initial=-1)) + 1):
        idx = np.flatnonzero(rve.cluster_id == c)
        if idx.size:
            out.append((idx, _unwrap(rve.centers_m[idx], rve.box_m)))
    return out


def chain_axis(centers_m: np.ndarray) -> np.ndarray:
    """Principal axis (unit 3-vector) of a group of unwrapped centres (largest-variance axis)."""
    x = centers_m - centers_m.mean(0)
    w, v = np.linalg.eigh(x.T @ x)
    return v[:, -1]


def describe(rve: RVE) -> dict:
    """Summary statistics of an RVE, SI units, JSON-serialisable.

    Keys: counts, box edge, target and achieved volume fraction, radius statistics (number and
    volume weighted), core radii, mass and moment totals, smallest surface gap, and for
    agglomerates their number, sizes, packing density and (chains) alignment order parameter
    S = <(3 cos^2 theta - 1) / 2> of the chain axes with ``chain_direction``.
    """
    r = rve.radii_m
    v = rve.particle_volumes_m3
    out = {
        "n": rve.n,
        "box_m": rve.box_m,
        "phi_target": rve.params.get("phi"),
        "phi": rve.phi,
        "phi_rel_error": (rve.phi / rve.params["phi"] - 1.0) if rve.params.get("phi") else None,
        "number_density_m3": rve.number_density_m3,
        "seed": rve.seed,
        "arrangement": rve.params.get("arrangement"),
        "radius_m": {
            "mean": float(r.mean()), "std": float(r.std()), "min": float(r.min()),
            "max": float(r.max()), "median": float(np.median(r)),
            "p10": float(np.percentile(r, 10)), "p90": float(np.percentile(r, 90)),
            "volume_weighted_mean": float(np.sum(v * r) / v.sum()),
        },
        "core_radius_mean_m": float(rve.core_radii_m.mean()),
        "mass_total_kg": float(rve.mass_kg.sum()),
        "m_sat_total_Am2": float(rve.m_sat_Am2.sum()),
        "specific_moment_Am2_kg": rve.specific_moment_Am2_kg,
        "M_sat_composite_A_m": float(rve.m_sat_Am2.sum() / rve.volume_m3),
        "min_gap_m": min_surface_gap_m(rve),
        "gap_m": rve.params.get("gap_m"),
    }
    groups = cluster_members(rve)
    cl = {"n_clusters": len(groups), "agglomerated_fraction":
          float(np.mean(rve.cluster_id >= 0)) if rve.n else 0.0}
    if groups:
        sizes = np.array([idx.size for idx, _x in groups])
        cl.update({"size_mean": float(sizes.mean()), "size_min": int(sizes.min()),
                   "size_max": int(sizes.max())})
        if rve.params.get("arrangement") == "chains":
            u = np.asarray(rve.params.get("chain_direction", (0, 0, 1)), float)
            cos = np.array([abs(chain_axis(x) @ u) for _idx, x in groups])
            cl["alignment_order_parameter"] = float(np.mean(1.5 * cos ** 2 - 0.5))
            cl["alignment_order_parameter_expected"] = chain_order_parameter(
                chain_kappa(float(rve.params.get("chain_spread_deg", 0.0))))
        else:
            dens = np.array([cluster_packing_density(x, rve.radii_m[idx]) for idx, x in groups])
            cl.update({"packing_density_mean": float(dens.mean()),
                       "packing_density_min": float(dens.min()),
                       "packing_density_max": float(dens.max())})
    out["clusters"] = cl
    return out
