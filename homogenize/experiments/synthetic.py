"""Synthetic experiments with a hidden cause: the test bench of ``diagnose``.

:func:`generate` draws, from a seed, an experiment in the spec's format: the seed model plus
zero, one or two hidden causes, each with a random but physically plausible magnitude, a random
design that can reveal it (several phi, fields, lengths, radii, shapes or branches as needed)
and 1-3 % Gaussian noise.

The truth is deliberately NOT the diagnosis model with other numbers. It is written here,
independently of ``causes.py``, and where physics allows in a different form:

============================== ==================================================================
cause                          truth used here                      (diagnosis fits)
============================== ==================================================================
field_dependent_magnetization  deflection: ``M_p = Ms tanh(chi H / Ms)``; magnetization:
                               log-normal mixture of Langevin moments   (FK / Langevin / linear)
dipolar_interaction            magnetostriction: ``kappa mu0 M^2 / E`` with ``kappa =
                               k_spheroid(aspect) - 1/5 + kappa0 (1 + phi)`` (Osborn spheroid
                               shape stress, Lorentz mean field); magnetization: Lorentz local
                               field on the tanh law  (cylinder shape stress, RVE virial table,
                               constant kappa_extra)
oxide_shell                    log-normal radii (gsd 1.3) around each specimen's mean, Fe core +
                               Fe3O4 shell, volume-weighted moment  (one radius per specimen)
filler_stiffening              Einstein-Batchelor ``1 + 2.5 phi + 6.2 phi^2``  (FEM table)
geometric_nonlinearity         elastica by shooting (solve_ivp + brentq, written here)
hyperelasticity                one-term Ogden, alpha in [0.8, 1.5] or [4, 5]  (NH / MR / Gent)
gravity                        self-weight ``rho_c g`` in an 'unloaded' reference
hysteresis                     tensile: Ogden-Roxburgh Mullins softening ``eta(W)``
                               (constant factor); magnetic: tanh law shifted by +-H_c
demagnetization                spheroid demagnetizing factor (Osborn 1945) of the same aspect
                               ratio                                 (cylinder factor)
microstructure_evolution       magnetostriction: gaps that close under the stress raise it
                               again, a geometric series ``strain = kappa x / (1 - b x)`` with
                               ``x = mu0 M^2 / E`` and b in [2, 4], on the tanh law (M must
                               vary within a specimen to show it)   (``kappa += c x``, fitted c)
============================== ==================================================================

Causes that act through a non-saturated magnetization (``dipolar_interaction`` in the
magnetization kind, ``hysteresis`` and ``demagnetization`` of magnetic kinds) cannot show on
saturated particles, so their truth includes ``field_dependent_magnetization`` and the expected
answer (``SyntheticCase.expected``) lists both. In the magnetostriction kind the seed model
predicts no strain, so ``dipolar_interaction`` (the strain's source) is always part of the truth.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy import integrate, optimize, special
from scipy.constants import mu_0

from micro.materials import FE, FE3O4, GRAVITY_M_S2, PDMS, SEED

from homogenize.experiments.io import Experiment, Matrix, Particles, Setup, _ro
from homogenize.experiments.io import write_experiment

__all__ = ["SyntheticCase", "generate", "CASES", "study_cases", "write_case"]

_MS = SEED.Ms_A_m               # the seed paper's particle saturation magnetization [A/m]
_E = PDMS.E_Pa

#: (hidden causes, kind) of the cases the tests and the study draw from.
CASES = (
    ((), "deflection"), ((), "magnetization"), ((), "tensile"),
    (("field_dependent_magnetization",), "magnetization"),
    (("field_dependent_magnetization",), "deflection"),
    (("dipolar_interaction",), "magnetostriction"),
    (("dipolar_interaction",), "magnetization"),
    (("oxide_shell",), "magnetization"),
    (("oxide_shell",), "deflection"),
    (("filler_stiffening",), "deflection"),
    (("filler_stiffening",), "tensile"),
    (("geometric_nonlinearity",), "deflection"),
    (("hyperelasticity",), "tensile"),
    (("gravity",), "deflection"),
    (("hysteresis",), "tensile"),
    (("hysteresis",), "magnetization"),
    (("demagnetization",), "magnetization"),
    (("geometric_nonlinearity", "gravity"), "deflection"),
    (("hyperelasticity", "hysteresis"), "tensile"),
    (("field_dependent_magnetization", "demagnetization"), "magnetization"),
    (("oxide_shell", "filler_stiffening"), "deflection"),
    (("field_dependent_magnetization", "geometric_nonlinearity"), "deflection"),
    (("microstructure_evolution",), "magnetostriction"),
)

_NEEDS_LAW = {"dipolar_interaction", "hysteresis", "demagnetization"}


@dataclass(frozen=True, eq=False)
class SyntheticCase:
    """A generated experiment and its truth."""
    hidden: tuple
    expected: frozenset           # causes a correct diagnosis names
    kind: str
    seed: int
    noise: float                  # relative noise level
    truth: dict                   # the drawn magnitudes
    experiment: Experiment


def _expected(hidden, kind):
    exp = set(hidden)
    if kind == "magnetostriction":
        exp.add("dipolar_interaction")
        if exp & {"hysteresis", "demagnetization", "microstructure_evolution"}:
            exp.add("field_dependent_magnetization")
    elif kind != "tensile" and exp & _NEEDS_LAW:
        exp.add("field_dependent_magnetization")
    return frozenset(exp)


def _stiffening_truth(phi):
    """Rigid spheres in an incompressible matrix to second order in phi: Einstein's 2.5 and
    Batchelor & Green's (J. Fluid Mech. 56 (1972) 401) 6.2 for a random suspension, by the
    elastic-viscous analogy."""
    return 1.0 + 2.5 * phi + 6.2 * phi ** 2


def _tanh_law(H, chi, Ms):
    return Ms * np.tanh(chi * H / Ms)


_GH_X, _GH_W = np.polynomial.hermite_e.hermegauss(16)
_GH_W = _GH_W / _GH_W.sum()


def _langevin_mixture(H, chi, Ms, sigma=0.5):
    """Polydisperse Langevin particles: log-normal moments (sd of ln m = sigma), mean initial
    susceptibility chi: ``Ms sum_i w_i L(3 chi_i H / Ms)``."""
    chis = chi * np.exp(sigma * _GH_X - 0.5 * sigma ** 2)
    x = 3.0 * np.multiply.outer(np.asarray(H, dtype=float), chis) / Ms
    xs = np.where(np.abs(x) < 1e-4, 1.0, x)
    L = np.where(np.abs(x) < 1e-4, x / 3.0, 1.0 / np.tanh(xs) - 1.0 / xs)
    return Ms * (L @ _GH_W)


def _spheroid_demag(m):
    """Axial demagnetizing factor of a spheroid with axis ratio m = c / a (Osborn 1945)."""
    m = np.asarray(m, dtype=float)
    out = np.empty_like(m)
    for i, x in np.ndenumerate(m):
        if abs(x - 1.0) < 1e-9:
            out[i] = 1.0 / 3.0
        elif x > 1:
            e = math.sqrt(x * x - 1.0)
            out[i] = (x / e * math.log(x + e) - 1.0) / (x * x - 1.0)
        else:
            e = math.sqrt(1.0 - x * x)
            out[i] = (1.0 - x / e * math.acos(x)) / (1.0 - x * x)
    return out


def _spheroid_shape_stress(m):
    """-(3/4) m dN/dm of a spheroid of axis ratio m (Osborn factor; central difference):
    the axial Maxwell stress over mu0 M^2 of a saturated spheroid stretched at fixed volume."""
    d = 1e-3                   # O(d^2) truncation; smaller steps lose digits near m = 1
    return float(-0.75 * m * (_spheroid_demag(m * (1 + d)) - _spheroid_demag(m * (1 - d))) / (2 * d * m))


def _elastica_tip(alpha):
    """delta / L of a clamped-free elastica under a uniform dead load, by shooting."""
    if alpha == 0.0:
        return 0.0
    sgn = math.copysign(1.0, alpha)
    a = abs(alpha)

    def rhs(s, y):  # y = (theta, theta', Y); theta'' = -a (1 - s) cos(theta)
        return [y[1], -a * (1.0 - s) * math.cos(y[0]), math.sin(y[0])]

    def tip_moment(k0):
        sol = integrate.solve_ivp(rhs, (0.0, 1.0), [0.0, k0, 0.0], rtol=1e-10, atol=1e-12)
        return sol.y[1, -1], sol.y[2, -1]

    k0 = optimize.brentq(lambda k: tip_moment(k)[0], 0.0, a / 2.0 * (1 + 1e-9), xtol=1e-13)
    return sgn * tip_moment(k0)[1]


def _noisy(rng, y, noise):
    scale = np.abs(y) + 0.02 * np.max(np.abs(y))
    return y + noise * scale * rng.standard_normal(y.size)


def _self_consistent(H_a, feedback, law, iters=200):
    """Solve M = law(H_a + feedback M) by damped fixed point (|feedback law'| < 1 here)."""
    M = law(H_a)
    for _ in range(iters):
        M = 0.5 * M + 0.5 * law(H_a + feedback * M)
    return M


# ------------------------------------------------------------------------------------------

def generate(hidden=(), kind: str | None = None, seed: int = 0, noise: float | None = None
             ) -> SyntheticCase:
    """Draw a synthetic experiment with the ``hidden`` causes.

    Parameters
    ----------
    hidden : tuple of str -- causes to hide (0, 1 or 2), from the spec's vocabulary
    kind : str or None -- experiment kind (None: the first kind listed in ``CASES`` for them)
    seed : int -- everything random is drawn from ``numpy.random.default_rng(seed)``
    noise : float or None -- relative noise level (None: drawn in [0.01, 0.03])
    """
    hidden = tuple(hidden)
    if kind is None:
        kind = next(k for h, k in CASES if set(h) == set(hidden))
    rng = np.random.default_rng(seed)
    noise = float(rng.uniform(0.01, 0.03)) if noise is None else float(noise)
    gen = {"deflection": _deflection, "magnetization": _magnetization,
           "magnetostriction": _magnetostriction, "tensile": _tensile}[kind]
    cols, truth, setup = gen(set(hidden), rng)
    y_name = {"deflection": "deflection_m", "magnetization": "M_A_per_m",
              "magnetostriction": "strain", "tensile": "stress_Pa"}[kind]
    cols[y_name] = _noisy(rng, np.asarray(cols[y_name], dtype=float), noise)
    specimen = np.asarray(cols.pop("specimen"), dtype=str)
    branch = cols.pop("branch", None)
    down = np.zeros(specimen.size, bool) if branch is None else np.asarray(branch) == "down"
    exp = Experiment(kind=kind, toml_path=None, data_path=None,
                     title=f"synthetic {kind}: hidden {', '.join(hidden) or 'nothing'} (seed {seed})",
                     matrix=Matrix(), particles=Particles(), setup=setup or Setup(),
                     columns={k: _ro(np.asarray(v, dtype=float)) for k, v in cols.items()},
                     specimen=_ro(specimen), down=_ro(down))
    truth["branch_present"] = branch is not None
    return SyntheticCase(hidden, _expected(hidden, kind), kind, seed, noise, truth, exp)


def _deflection(h, rng):
    truth = {}
    n_spec = 6
    per = 6
    scale = float(rng.uniform(0.3, 1.0))
    truth["scale"] = scale
    geo = "geometric_nonlinearity" in h
    filler = "filler_stiffening" in h
    oxide = "oxide_shell" in h
    fdm = "field_dependent_magnetization" in h
    grav = "gravity" in h
    chi = float(rng.uniform(0.5, 3.0)) if fdm else None
    if fdm:
        truth["chi_tanh"] = chi
    shell = float(rng.uniform(1.5e-9, 4e-9)) if oxide else 0.0
    if oxide:
        truth["shell_m"] = shell
    cols = {k: [] for k in ("specimen", "phi", "length_m", "width_m", "thickness_m", "B_T",
                            "gradB_T_per_m", "deflection_m", "radius_mean_m")}
    for s in range(n_spec):
        t = float(rng.uniform(0.5e-3, 2e-3))
        w = float(rng.uniform(3e-3, 8e-3))
        phi = float(rng.uniform(0.02, 0.15)) if filler else float(rng.uniform(0.01, 0.05))
        r = float(rng.uniform(8e-9, 50e-9)) if oxide else 25e-9
        Ms = _MS * (_shell_ratio(r, shell) if oxide else 1.0)
        E = _E * (_stiffening_truth(phi) if filler else 1.0)
        if fdm:
            B = np.geomspace(0.01, 1.0, per) * float(rng.uniform(0.8, 1.2))
            Mp = _tanh_law(B / mu_0, chi, Ms)
            gradB = float(rng.uniform(2.0, 10.0)) * B     # a coil: gradient ~ field
        else:
            # a coil: field and gradient both follow the current
            gradB = np.linspace(0.15, 1.0, per) * float(rng.uniform(1.0, 10.0))
            B = gradB / gradB[-1] * float(rng.uniform(0.3, 1.0))
            Mp = np.full(per, Ms)
        f = scale * phi * Mp * gradB
        # design: the length makes the largest load reach alpha_max = q L^3 / EI
        alpha_max = float(rng.uniform(2.0, 8.0)) if geo else float(rng.uniform(0.05, 0.4))
        L = (alpha_max * E * t ** 2 / (12.0 * float(np.max(np.abs(f))))) ** (1.0 / 3.0)
        L = float(np.clip(L, 5e-3, 80e-3))
        EI = E * w * t ** 3 / 12.0
        if grav:
            # zero-field rows reveal self-weight; 'unloaded' reference
            gradB = np.concatenate(([0.0], gradB[1:]))
            B = np.concatenate(([0.0], B[1:]))
            f = np.concatenate(([0.0], f[1:]))
            fg = ((1 - phi) * PDMS.density_kg_m3 + phi * FE.density_kg_m3) * GRAVITY_M_S2
            f = f + fg
        alpha = f * w * t * L ** 3 / EI
        if geo:
            d = np.array([_elastica_tip(a) for a in alpha]) * L
        else:
            d = alpha / 8.0 * L
        cols["specimen"] += [f"S{s + 1}"] * per
        cols["phi"] += [phi] * per
        cols["length_m"] += [L] * per
        cols["width_m"] += [w] * per
        cols["thickness_m"] += [t] * per
        cols["B_T"] += list(B)
        cols["gradB_T_per_m"] += list(gradB)
        cols["deflection_m"] += list(d)
        cols["radius_mean_m"] += [r] * per
    if not oxide:
        del cols["radius_mean_m"]
    setup = Setup(deflection_reference="unloaded") if grav else Setup()
    return cols, truth, setup


def _shell_ratio(r, shell, gsd=1.3, nominal=25e-9):
    """Volume-averaged Ms of log-normal core-shell particles around mean r over that around
    the nominal radius (truth for oxide_shell; 64-point Gauss-Hermite over log r)."""
    x, wts = np.polynomial.hermite_e.hermegauss(64)
    wts = wts / wts.sum()

    def mean_ms(rm):
        rr = rm * np.exp(math.log(gsd) * x - 0.5 * math.log(gsd) ** 2)
        rc = np.clip(rr - shell, 0.0, None)
        m = (FE.sigma_s_Am2_kg * FE.density_kg_m3 * rc ** 3
             + FE3O4.sigma_s_Am2_kg * FE3O4.density_kg_m3 * (rr ** 3 - rc ** 3))
        return float(np.sum(wts * m) / np.sum(wts * rr ** 3))
    return mean_ms(r) / mean_ms(nominal)


def _magnetization(h, rng):
    truth = {}
    fdm = bool(h & ({"field_dependent_magnetization"} | _NEEDS_LAW))
    dip = "dipolar_interaction" in h
    hyst = "hysteresis" in h
    demag = "demagnetization" in h
    oxide = "oxide_shell" in h
    scale = float(rng.uniform(0.3, 1.0))
    truth["scale"] = scale
    # soft spheres: apparent susceptibility near its limit 3 where interactions must show
    chi = float(rng.uniform(2.0, 3.0) if (dip or demag) else rng.uniform(0.5, 3.0)) if fdm else None
    if fdm:
        truth["chi_langevin_mixture"] = chi
    shell = float(rng.uniform(1.5e-9, 4e-9)) if oxide else 0.0
    if oxide:
        truth["shell_m"] = shell
    Hc = None
    if hyst:
        Hc = float(rng.uniform(0.02, 0.1)) * _MS / chi
        truth["H_c_A_per_m"] = Hc
    n_spec = 6 if (oxide or demag or dip) else 2
    cols = {k: [] for k in ("specimen", "phi", "H_A_per_m", "M_A_per_m", "radius_mean_m",
                            "aspect_ratio", "branch")}
    for s in range(n_spec):
        phi = float(rng.uniform(0.1, 0.4)) if (dip or demag) else float(rng.uniform(0.02, 0.2))
        r = float(rng.uniform(8e-9, 50e-9)) if oxide else 25e-9
        aspect = float(np.exp(rng.uniform(math.log(0.15), math.log(6.0)))) if demag else 1.0
        Ms = _MS * (_shell_ratio(r, shell) if oxide else 1.0)
        if fdm:
            Hs = Ms / chi
            # interactions and demagnetization show in the initial susceptibility: a low-field
            # design for them; up to 6 saturation fields otherwise
            H = np.geomspace(0.02, 1.5 if (dip or demag) else 6.0, 10) * Hs
        else:
            H = np.geomspace(2e5, 3e6, 6)
        branches = ["up"] * H.size
        if hyst:
            H = np.concatenate((H, H[::-1][1:]))
            branches = ["up"] * (H.size // 2 + 1) + ["down"] * (H.size // 2)
        down = np.array(branches) == "down"
        shift = np.where(down, 1.0, -1.0) * Hc if hyst else 0.0
        N = _spheroid_demag(aspect) if demag else 0.0
        feedback = (1.0 / 3.0 if dip else 0.0) - N
        if fdm:
            law = lambda Hl: scale * phi * _langevin_mixture(Hl + shift, chi, Ms)
            M = _self_consistent(H, feedback, law)
        else:
            M = np.full(H.size, scale * phi * Ms)
        n = H.size
        cols["specimen"] += [f"S{s + 1}"] * n
        cols["phi"] += [phi] * n
        cols["H_A_per_m"] += list(H)
        cols["M_A_per_m"] += list(M)
        cols["radius_mean_m"] += [r] * n
        cols["aspect_ratio"] += [aspect] * n
        cols["branch"] += branches
    if not oxide:
        del cols["radius_mean_m"]
    if not demag:
        del cols["aspect_ratio"]
    if not hyst:
        del cols["branch"]
    return cols, truth, None


def _magnetostriction(h, rng):
    truth = {}
    fdm = "field_dependent_magnetization" in h or bool(h & {"hysteresis", "demagnetization",
                                                             "microstructure_evolution"})
    kappa0 = float(rng.uniform(0.3, 2.0))
    truth["kappa0"] = kappa0
    if "microstructure_evolution" in h:
        truth["b_restructure"] = float(rng.uniform(2.0, 4.0))
    chi = float(rng.uniform(0.5, 3.0)) if fdm else None
    cols = {k: [] for k in ("specimen", "phi", "aspect_ratio", "B_T", "strain")}
    n_spec = 6
    for s in range(n_spec):
        phi = float(rng.uniform(0.05, 0.3))
        aspect = float(rng.uniform(0.5, 2.0))
        B = np.linspace(0.3, 1.5, 6) if not fdm else np.linspace(0.02, 1.5, 8)
        H = B / mu_0
        M = phi * (_tanh_law(H, chi, _MS) if fdm else np.full(H.size, _MS))
        # affine mean field: the shape's Maxwell stress (spheroid of the same aspect ratio)
        # minus the Lorentz cavity's 1/5, plus a phi-dependent stress it does not explain
        kappa = _spheroid_shape_stress(aspect) - 0.2 + kappa0 * (1.0 + phi)
        x = mu_0 * M ** 2 / _E
        strain = kappa * x
        if "microstructure_evolution" in h:
            # restructuring: the stress closes gaps, which raises the stress (geometric series)
            strain = strain / (1.0 - truth["b_restructure"] * x)
        n = B.size
        cols["specimen"] += [f"S{s + 1}"] * n
        cols["phi"] += [phi] * n
        cols["aspect_ratio"] += [aspect] * n
        cols["B_T"] += list(B)
        cols["strain"] += list(strain)
    return cols, truth, None


def _ogden(lam, G, a):
    return 2.0 * G / a * (lam ** (a - 1.0) - lam ** (-a / 2.0 - 1.0))


def _tensile(h, rng):
    truth = {}
    hyper = "hyperelasticity" in h
    hyst = "hysteresis" in h
    filler = "filler_stiffening" in h
    E0 = float(np.exp(rng.uniform(math.log(0.5e6), math.log(3e6))))
    truth["E_Pa"] = E0
    a = None
    if hyper:
        # alpha near 3 gives an engineering stress almost proportional to strain up to
        # stretch 3 (lam^2 - lam^-2.5 ~ linear): no visible effect, so it is left out
        a = float(rng.choice([rng.uniform(0.8, 1.5), rng.uniform(4.0, 5.0)]))
        truth["ogden_alpha"] = a
    r_or = m_or = None
    if hyst:
        r_or = float(rng.uniform(1.2, 3.0))
        truth["ogden_roxburgh_r"] = r_or
    cols = {k: [] for k in ("specimen", "phi", "strain", "stress_Pa", "branch")}
    n_spec = 4 if filler else 3
    # one test protocol for the series: every specimen pulled to about the same strain
    e_target = float(rng.uniform(0.8, 1.8)) if hyper else float(rng.uniform(0.05, 0.12))
    for s in range(n_spec):
        phi = float(rng.uniform(0.0, 0.25)) if filler else 0.0
        E = E0 * (_stiffening_truth(phi) if filler else 1.0)
        emax = e_target * float(rng.uniform(0.95, 1.05))
        e_up = np.linspace(emax / 10, emax, 10)
        lam = 1.0 + e_up
        sig_up = _ogden(lam, E / 3.0, a) if hyper else E * e_up
        e, sig, br = list(e_up), list(sig_up), ["up"] * e_up.size
        if hyst:
            e_dn = e_up[::-1][1:]
            lam_d = 1.0 + e_dn
            if hyper:
                W = lambda l: 2 * (E / 3.0) / a ** 2 * (l ** a + 2 * l ** (-a / 2) - 3)
                sdn = _ogden(lam_d, E / 3.0, a)
            else:
                W = lambda l: 0.5 * E * (l - 1.0) ** 2
                sdn = E * e_dn
            Wm = W(lam[-1])
            m_or = 0.3 * Wm
            eta = 1.0 - special.erf((Wm - W(lam_d)) / m_or) / r_or
            e += list(e_dn)
            sig += list(eta * sdn)
            br += ["down"] * e_dn.size
        n = len(e)
        cols["specimen"] += [f"T{s + 1}"] * n
        cols["phi"] += [phi] * n
        cols["strain"] += e
        cols["stress_Pa"] += sig
        cols["branch"] += br
    if not hyst:
        del cols["branch"]
    return cols, truth, None


def study_cases(n: int, seed: int = 0):
    """``n`` (hidden, kind, seed) triples cycling through :data:`CASES`."""
    return [(CASES[i % len(CASES)][0], CASES[i % len(CASES)][1], seed + i) for i in range(n)]


def write_case(case: SyntheticCase, toml_path) -> Path:
    """Write a synthetic case as TOML + CSV in the spec's format."""
    e = case.experiment
    cols = {"specimen": list(e.specimen)}
    for k, v in e.columns.items():
        cols[k] = list(v)
    if case.truth.get("branch_present"):
        cols["branch"] = ["down" if d else "up" for d in e.down]
    write_experiment(toml_path, e.kind, cols, title=e.title, setup=e.setup)
    return Path(toml_path)
