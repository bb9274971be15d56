"""The physics the extensions are built from: narrow adapters onto the project's modules, plus
the few small material laws this package owns.

Owned here (each tested in tests/homogenize/experiments/test_experiment_physics.py):

* :func:`cylinder_demag_factor` -- magnetometric demagnetizing factor of a cylinder magnetized
  along its axis, from the exact end-face-charge integral
  ``N = (2R/L) int_0^inf J1(u)^2 / u^2 (1 - exp(-u L / R)) du``.
* :func:`uniaxial_stress_Pa` -- engineering (nominal) stress of incompressible hyperelastic
  laws in uniaxial tension: neo-Hookean, Mooney-Rivlin, Gent.

Adapters (the physics lives elsewhere in the project; nothing is re-implemented):

* beams -- ``homogenize.macro.closed_form`` (Euler-Bernoulli compliance, elastica table),
* magnetization laws -- ``micro.magnetization.get_law``,
* filler stiffening -- the voxel-FEM table of ``homogenize.cell.problem`` (module ``tables``),
* core-shell moments -- ``micro.particles``.

An extension whose precomputed table is missing raises :class:`Unavailable`; the diagnosis
then leaves that cause out and says so, rather than faking it.
"""
from __future__ import annotations

import csv
import functools
import math
from pathlib import Path

import numpy as np
from scipy import integrate, special
from scipy.constants import mu_0

from micro import dipoles, magnetization, particles

from homogenize.cell import problem as cellmod
from homogenize.experiments.rve_tables import Unavailable, filler_stiffness_ratio
from homogenize.macro import closed_form
from micro.common.files import atomic_write_text
from micro.common.validate import InputError
from micro.materials import FE, PDMS
from scipy.interpolate import CubicSpline
from scipy.constants import k as kB

__all__ = ["local_field_factor", "dipolar_local_field_point", "Unavailable", "cylinder_demag_factor", "shape_stress_coefficient", "uniaxial_stress_Pa", "HYPERELASTIC_FORMS",
           "eb_compliance_m4_N", "elastica_ratio", "LAWS", "particle_magnetization_A_per_m",
           "stiffening_ratio", "core_shell_moment_ratio", "composite_density_kg_m3", "mu_0",
           "elastica_table_path"]

DATA_DIR = Path(__file__).resolve().parent / "data"


# ------------------------------------------------------------------------------------------
# demagnetizing factor of a cylinder (owned here)

@functools.lru_cache(maxsize=4096)
def _demag_scalar(aspect: float) -> float:
    # The integral of micro.demag.cylinder_demag_factors (N_z at L / R = 2 aspect) by another
    # quadrature: the two agree to ~1e-8 relative for aspect 0.1-10 (6e-4 at aspect 100), not
    # bit for bit, so replacing this by that call would move the diagnosis' numbers (issue 33).
    # u = k R; end faces are disks of radius R a distance L = 2 R aspect apart
    ratio = 2.0 * aspect                       # L / R
    f = lambda u: (special.j1(u) / u) ** 2 * -math.expm1(-u * ratio) if u > 0 else 0.0
    # pieces of length pi up to U = 200 pi so quad sees smooth arches; beyond U, J1^2 averages
    # to 1 / (pi u) (J1 ~ sqrt(2 / (pi u)) cos(u - 3 pi / 4)), so the tail is the smooth
    # integral of (1 - exp(-u L/R)) / (pi u^3) (at most 1 / (2 pi U^2) = 4e-7).
    edges = np.arange(0, 201) * math.pi
    total = 0.0
    for a, b in zip(edges[:-1], edges[1:]):
        val, _ = integrate.quad(f, a, b, limit=100, epsabs=1e-14, epsrel=1e-12)
        total += val
    tail, _ = integrate.quad(lambda u: -math.expm1(-u * ratio) / (math.pi * u ** 3),
                             edges[-1], np.inf, epsabs=1e-15)
    total += tail
    return total / aspect                      # (2R/L) = 1/aspect


def cylinder_demag_factor(aspect_ratio):
    """Magnetometric (volume-averaged) demagnetizing factor of a cylinder along its axis.

    Parameters
    ----------
    aspect_ratio : float or ndarray -- length / diameter [-], > 0

    Returns
    -------
    float or ndarray -- N in (0, 1); N -> 1 for a thin disk, N -> 4 / (3 pi aspect) for a
    long rod (energy of the two charged end faces, sigma = +-M).
    """
    a = np.asarray(aspect_ratio, dtype=float)
    if np.any(~np.isfinite(a)) or np.any(a <= 0):
        raise InputError(f"aspect_ratio must be finite and > 0, got {aspect_ratio!r}")
    out = np.array([_demag_scalar(float(x)) for x in a.ravel()]).reshape(a.shape)
    return float(out) if out.ndim == 0 else out


def shape_stress_coefficient(aspect_ratio):
    """Axial magnetic (Maxwell) stress of the specimen's shape over ``mu0 M^2`` [-].

    A cylinder magnetized along its axis with fixed M stores the demagnetizing energy
    ``(1/2) mu0 N M^2 V``. Stretching it axially by eps at constant volume raises its aspect
    ratio by ``(3/2) a eps``, so the energy falls at the rate ``(3/4) a N'(a) mu0 M^2 V``: the
    specimen is pulled along the field by the stress ``-(3/4) a dN/da mu0 M^2`` (positive:
    elongation). ``N`` is :func:`cylinder_demag_factor`; its derivative by a central
    difference of relative step 1e-4 (N is integrated to ~1e-12: error ~1e-8).

    For a sphere (not a cylinder) the same formula gives 1/5 (``N = 1/3 - (4/15) e`` for a
    spheroid of axis ratio 1 + e), exactly the mean-field (Lorentz) stress of the particles'
    own interactions: a spherical specimen of randomly dispersed particles does not strain in
    the mean-field, affine picture. Long rod: ``1 / (pi a)``.
    """
    a = np.asarray(aspect_ratio, dtype=float)
    d = 1e-4
    dN = (cylinder_demag_factor(a * (1 + d)) - cylinder_demag_factor(a * (1 - d))) / (2 * d * a)
    out = -0.75 * a * dN
    return float(out) if np.ndim(out) == 0 else out


# ------------------------------------------------------------------------------------------
# hyperelastic matrix in uniaxial tension (owned here)

HYPERELASTIC_FORMS = ("neo-hookean", "mooney-rivlin", "gent")


def uniaxial_stress_Pa(form: str, strain, E_Pa: float, extra: float | None = None):
    """Engineering stress of an incompressible hyperelastic solid in uniaxial tension.

    Parameters
    ----------
    form : {"neo-hookean", "mooney-rivlin", "gent"}
    strain : ndarray -- engineering strain, stretch ``lam = 1 + strain`` [-]
    E_Pa : float -- small-strain Young's modulus, ``E = 3 G`` [Pa]
    extra : float -- Mooney-Rivlin: ``beta = C2 / (C1 + C2)`` [-]; Gent: ``J_m`` [-]

    Returns
    -------
    ndarray -- nominal stress [Pa]. Every form has slope E at zero strain.

    Notes
    -----
    neo-Hookean ``P = G (lam - lam^-2)``; Mooney-Rivlin ``P = 2 (C1 + C2 / lam)(lam - lam^-2)``
    with ``G = 2 (C1 + C2)``; Gent ``P = G J_m (lam - lam^-2) / (J_m - I1 + 3)``,
    ``I1 = lam^2 + 2 / lam`` (the stress diverges as I1 - 3 -> J_m: chain locking).
    """
    lam = 1.0 + np.asarray(strain, dtype=float)
    G = E_Pa / 3.0
    base = lam - lam ** -2
    if form == "neo-hookean":
        return G * base
    if form == "mooney-rivlin":
        beta = 0.0 if extra is None else float(extra)
        return G * ((1.0 - beta) + beta / lam) * base
    if form == "gent":
        Jm = float(extra)
        I1 = lam ** 2 + 2.0 / lam
        denom = np.maximum(Jm - I1 + 3.0, 1e-9 * Jm)    # past locking: very stiff, not NaN
        return G * Jm * base / denom
    raise ValueError(f"unknown hyperelastic form {form!r}")


# ------------------------------------------------------------------------------------------
# beams: adapters onto homogenize.macro.closed_form

def eb_compliance_m4_N(length_m, width_m, thickness_m, E_Pa):
    """Euler-Bernoulli tip deflection per unit body force, row by row [m / (N/m^3)].

    Calls ``homogenize.macro.closed_form.eb_tip_deflection_m`` with f = 1 N/m^3 per distinct
    geometry (the deflection is linear in f).
    """
    cf = closed_form
    L, w, t = (np.atleast_1d(np.asarray(x, dtype=float)) for x in (length_m, width_m, thickness_m))
    E = np.broadcast_to(np.asarray(E_Pa, dtype=float), L.shape)
    out = np.empty(L.shape)
    cache = {}
    for i in range(L.size):
        key = (L[i], w[i], t[i], E[i])
        if key not in cache:
            cache[key] = cf.eb_tip_deflection_m(1.0, L[i], w[i], t[i], E[i])
        out[i] = cache[key]
    return out


_ELASTICA_ALPHA_MAX = 1.0e4          # delta / L = 0.994 there


def elastica_table_path() -> Path:
    return DATA_DIR / "elastica_table.csv"


@functools.lru_cache(maxsize=1)
def _elastica_table():
    """(log alpha, ratio) with ratio = (delta/L) / (alpha/8): elastica over Euler-Bernoulli.

    Built once from ``homogenize.macro.closed_form.elastica_tip_deflection`` (unit beam with
    EI = 1 so that alpha = f) and stored in data/elastica_table.csv with how it was made.
    """
    path = elastica_table_path()
    if path.exists():
        rows = [r for r in csv.reader(path.read_text().splitlines()) if r and not r[0].startswith("#")]
        arr = np.array([[float(x) for x in r] for r in rows[1:]])
        return np.log(arr[:, 0]), arr[:, 1] / (arr[:, 0] / 8.0)
    cf = closed_form
    alpha = np.geomspace(1e-3, _ELASTICA_ALPHA_MAX, 201)
    # unit beam: L = w = 1, t = 1, E = 12  ->  EI = E w t^3 / 12 = 1, alpha = f w t L^3 / EI = f
    v, _ = cf.elastica_tip_deflection(alpha, 1.0, 1.0, 1.0, 12.0)
    lines = ["# elastica tip deflection of a clamped-free beam under a uniform dead load",
             "# made by homogenize.experiments._physics._elastica_table() from",
             "# homogenize.macro.closed_form.elastica_tip_deflection (solve_bvp, tol 1e-9) on a",
             "# unit beam (L = 1, EI = 1); alpha = q L^3 / (E I), delta_over_L = tip deflection / L",
             "alpha,delta_over_L"]
    lines += [f"{float(a)!r},{float(d)!r}" for a, d in zip(alpha, v)]
    try:
        atomic_write_text(path, "\n".join(lines) + "\n")
    except OSError:
        pass                                   # read-only install: keep the table in memory
    return np.log(alpha), np.asarray(v) / (alpha / 8.0)


def elastica_ratio(alpha):
    """Elastica tip deflection over the Euler-Bernoulli one at load ``alpha = q L^3 / EI``.

    Interpolated (cubic in log alpha) in the stored table (alpha in [1e-3, 1e4]); 1 below the
    table (the correction is O(alpha^2) < 1e-7 there); above it the heavy-load asymptote
    ``delta / L = 1 - (2 - sqrt 2) / sqrt(alpha) + c / alpha`` with ``c`` matched to the table's
    last node (the neglected term is O(alpha^-3/2), < 1e-6 beyond 1e4).
    """
    la, ratio = _elastica_table()
    a = np.abs(np.asarray(alpha, dtype=float))
    out = np.ones_like(a)
    a_max = math.exp(la[-1])
    mid = (a > math.exp(la[0])) & (a <= a_max)
    if np.any(mid):
        out[mid] = _interp_cubic(la, ratio, np.log(a[mid]))
    big = a > a_max
    if np.any(big):
        d_max = ratio[-1] * a_max / 8.0
        c = (d_max - 1.0 + _HEAVY_LOAD / math.sqrt(a_max)) * a_max
        d = 1.0 - _HEAVY_LOAD / np.sqrt(a[big]) + c / a[big]
        out[big] = d / (a[big] / 8.0)
    return out


#: delta / L = 1 - _HEAVY_LOAD / sqrt(alpha) + O(1 / alpha) for a heavy load (clamp boundary
#: layer; see tests/homogenize/macro/test_closed_form.py)
_HEAVY_LOAD = 2.0 - math.sqrt(2.0)


@functools.lru_cache(maxsize=1)
def _spline():
    la, ratio = _elastica_table()
    return CubicSpline(la, ratio)


def _interp_cubic(la, ratio, x):
    return _spline()(x)


# ------------------------------------------------------------------------------------------
# magnetization laws: adapter onto micro.magnetization

LAWS = ("langevin", "frohlich-kennelly", "linear")


def particle_magnetization_A_per_m(law: str, H_A_per_m, Ms_A_per_m, chi0: float):
    """Magnetization of one particle [A/m] along H for a law with initial susceptibility chi0.

    Every law is parametrised by its saturation magnetization ``Ms`` and its initial
    susceptibility ``chi0 = dM/dH`` at H = 0, so that the laws differ only in shape. The law
    itself is ``micro.magnetization.get_law`` (see :func:`_project_law`). Odd in H.
    """
    H = np.asarray(H_A_per_m, dtype=float)
    Ms = np.broadcast_to(np.asarray(Ms_A_per_m, dtype=float), H.shape)
    return np.sign(H) * _project_law(law, np.abs(H), Ms, float(chi0))


_LANGEVIN_T_K = 300.0


def langevin_moment_Am2(chi0: float, Ms_A_per_m: float) -> float:
    """Particle moment whose Langevin law at 300 K has initial susceptibility chi0 [A m^2].

    ``chi0 = mu0 m Ms / (3 k_B T)`` (the slope of ``Ms L(mu0 m H / k_B T)`` at H = 0).
    """
    return 3.0 * kB * _LANGEVIN_T_K * chi0 / (mu_0 * Ms_A_per_m)


def _project_law(law, H_abs, Ms, chi0):
    """Map (law, chi0) onto micro.magnetization's own parameters and evaluate |M| [A/m].

    * linear: ``LinearLaw(chi)`` has apparent susceptibility ``3 chi / (3 + chi)``, so
      ``chi = 3 chi0 / (3 - chi0)`` (a sphere's apparent susceptibility is below 3);
    * frohlich-kennelly: ``chi0`` is the law's own parameter;
    * langevin: at T = 300 K, the moment ``m = 3 k_B T chi0 / (mu0 Ms)`` and volume ``m / Ms``.
    """
    mag = magnetization
    if law == "linear":
        c = min(chi0, 3.0 * (1.0 - 1e-12))
        obj = mag.get_law("linear", chi=3.0 * c / (3.0 - c))
        V = 1.0
        return np.asarray(obj.magnitude(H_abs, Ms * V, V), dtype=float) / V
    if law == "frohlich-kennelly":
        obj = mag.get_law("frohlich-kennelly", chi0=chi0)
        V = 1.0
        return np.asarray(obj.magnitude(H_abs, Ms * V, V), dtype=float) / V
    if law == "langevin":
        obj = mag.get_law("langevin", T_K=_LANGEVIN_T_K)
        # one moment per distinct Ms (rows may differ through the oxide shell)
        m = 3.0 * kB * _LANGEVIN_T_K * chi0 / (mu_0 * Ms)
        V = m / Ms
        return np.asarray(obj.magnitude(H_abs, m, V), dtype=float) / V
    raise ValueError(f"unknown law {law!r}")


# ------------------------------------------------------------------------------------------
# dipolar interaction: local-field factor of random RVEs from micro.dipoles (tabulated)

DIPOLAR_TABLE_PHI = (0.02, 0.05, 0.1, 0.15, 0.2, 0.25, 0.3, 0.35, 0.4)
DIPOLAR_TABLE_SEEDS = (1, 2, 3)
DIPOLAR_TABLE_N = 200
_DIPOLAR_H = 100.0            # A/m: linear regime (chi0 H / Ms ~ 2e-4)
_DIPOLAR_CHI0 = 3.0           # soft spheres at the demagnetization limit


def dipolar_table_path() -> Path:
    return DATA_DIR / "dipolar_local_field.csv"


def dipolar_local_field_point(phi: float, seed: int) -> float:
    """Local-field factor c of one random RVE: ``M = chi_c (H + c M)`` with ``chi_c = phi chi0``.

    ``micro.particles.generate_rve(phi, 200, seed)`` (monodisperse 25 nm, dispersed) and
    ``micro.dipoles.solve`` (periodic Ewald sums, no specimen demagnetization) with the
    Froehlich-Kennelly law at chi0 = 3 in the linear regime (H = 100 A/m):
    ``c = 1 / chi_c - H / M_eff``. The Lorentz cavity gives c = 1/3.
    """
    parts = particles
    dip = dipoles
    rve = parts.generate_rve(float(phi), DIPOLAR_TABLE_N, int(seed),
                             distribution=parts.Monodisperse(25e-9))
    st = dip.solve(rve, mu_0 * _DIPOLAR_H, 0.0, "frohlich-kennelly", chi0=_DIPOLAR_CHI0)
    M = float(st.M_eff_A_per_m[2])
    return 1.0 / (float(phi) * _DIPOLAR_CHI0) - _DIPOLAR_H / M


@functools.lru_cache(maxsize=1)
def _dipolar_table():
    path = dipolar_table_path()
    if path.exists():
        rows = [r for r in csv.reader(path.read_text().splitlines()) if r and not r[0].startswith("#")]
        arr = np.array([[float(x) for x in r] for r in rows[1:]])
        phis = np.unique(arr[:, 0])
        return phis, np.array([arr[arr[:, 0] == p, 2].mean() for p in phis])
    vals = [(p, s, dipolar_local_field_point(p, s)) for p in DIPOLAR_TABLE_PHI
            for s in DIPOLAR_TABLE_SEEDS]
    lines = ["# local-field factor c of random dispersed RVEs: M = phi chi0 (H + c M)",
             "# made by homogenize.experiments._physics._dipolar_table() with",
             "# dipolar_local_field_point(phi, seed): micro.particles.generate_rve(phi, 200, seed,",
             "# Monodisperse(25 nm)) + micro.dipoles.solve (Ewald, no demag), Froehlich-Kennelly",
             "# chi0 = 3, H = 100 A/m (linear regime). Lorentz cavity (mean field): c = 1/3.",
             "phi,seed,c"]
    lines += [f"{p!r},{s},{c!r}" for p, s, c in vals]
    try:
        atomic_write_text(path, "\n".join(lines) + "\n")
    except OSError:
        pass
    arr = np.array(vals)
    phis = np.unique(arr[:, 0])
    return phis, np.array([arr[arr[:, 0] == p, 2].mean() for p in phis])


def local_field_factor(phi):
    """Local-field factor c(phi) of randomly dispersed particles, ``H_loc = H + c M`` [-].

    Linear interpolation in the RVE table (mean over seeds), held constant outside
    [0.02, 0.4]. The table is built once from ``micro.dipoles`` (see
    :func:`dipolar_local_field_point`) and stored in data/dipolar_local_field.csv.
    """
    phis, c = _dipolar_table()
    return np.interp(np.asarray(phi, dtype=float), phis, c)


# ------------------------------------------------------------------------------------------
# filler stiffening: adapter onto homogenize.cell.problem closed forms

#: Iron particles (the FEM helper's defaults for ``homogenize_rve``).
PARTICLE_E_PA, PARTICLE_NU = FE.E_Pa, FE.nu


def stiffening_ratio(phi, nu_matrix: float = PDMS.nu, E_matrix_Pa: float = PDMS.E_Pa):
    """E_eff / E_matrix of iron spheres at volume fraction phi [-]: the project's voxel-FEM
    homogenization of random RVEs, tabulated (``tables.filler_stiffness_ratio``; Fe / PDMS
    contrast 1e5, i.e. rigid spheres, matrix nu = 0.45). ``nu_matrix`` and ``E_matrix_Pa`` are
    accepted for the adapter's signature; the ratio does not depend on E_matrix at this
    contrast, and the table is for nu = 0.45 (see ``filler_stiffness_ratio``)."""
    return filler_stiffness_ratio(phi)


def mori_tanaka_stiffening_ratio(phi, nu_matrix: float, E_matrix_Pa: float = PDMS.E_Pa):
    """The Mori-Tanaka estimate of ``homogenize.cell.problem`` for the same particles (the
    Hashin-Shtrikman bound on the matrix side): a cross-check of the FEM table only."""
    cell = cellmod
    Km, Gm = cell.bulk_shear(E_matrix_Pa, nu_matrix)
    Kp, Gp = cell.bulk_shear(PARTICLE_E_PA, PARTICLE_NU)
    K, G = cell.mori_tanaka(np.asarray(phi, dtype=float), Km, Gm, Kp, Gp)
    E, _ = cell.young_poisson(K, G)
    return np.asarray(E) / E_matrix_Pa


# ------------------------------------------------------------------------------------------
# core-shell particles: adapter onto micro.particles

def core_shell_moment_ratio(radius_m, shell_m, nominal_radius_m, core_density_kg_m3,
                            powder_sigma_Am2_kg):
    """Saturation magnetization of a core-shell particle of radius r over that at the powder's
    nominal radius [-], from ``micro.particles.CoreShell``.

    The powder's specific moment ``powder_sigma`` was measured on particles of the nominal
    radius; ``CoreShell(calibrate_sigma_Am2_kg=powder_sigma)`` picks the Fe core moment that
    reproduces it there, and ``CoreShell.apply`` gives every radius its moment. Smaller particles
    have a larger Fe3O4 fraction, hence less moment per volume. Ratio 1 at the nominal radius.
    """
    P = particles
    r = np.atleast_1d(np.asarray(radius_m, dtype=float))
    cs = P.CoreShell(shell_m=float(shell_m), core_density_kg_m3=float(core_density_kg_m3),
                     calibrate_sigma_Am2_kg=float(powder_sigma_Am2_kg))
    nominal = P.Monodisperse(float(nominal_radius_m))
    try:
        core_sigma = cs.core_sigma(nominal)
    except InputError:
        # this shell alone would carry more than the powder's sigma_s: not a physical state;
        # NaN makes the fit's residual huge there instead of stopping the diagnosis
        return np.full(r.shape, np.nan)
    _, _, m_0 = cs.apply(np.array([float(nominal_radius_m)]), core_sigma)
    per_volume_0 = m_0[0] / (4.0 / 3.0 * math.pi * float(nominal_radius_m) ** 3)
    # a particle no larger than the shell thickness is all oxide (CoreShell refuses it)
    out = np.full(r.shape, cs.shell_sigma_Am2_kg * cs.shell_density_kg_m3 / per_volume_0)
    cored = r > float(shell_m)
    if np.any(cored):
        _, _, m_r = cs.apply(r[cored], core_sigma)
        out[cored] = m_r / (4.0 / 3.0 * math.pi * r[cored] ** 3) / per_volume_0
    return out


def composite_density_kg_m3(phi, rho_matrix, rho_particle):
    """Rule of mixtures (exact for a mass balance): (1 - phi) rho_m + phi rho_p [kg/m^3]."""
    phi = np.asarray(phi, dtype=float)
    return (1.0 - phi) * rho_matrix + phi * rho_particle
