"""The one source of material constants: Fe, Fe3O4, PDMS, the seed paper's parameters and the
named presets of particles and matrices (``--particle-material``, ``--matrix-material``).

Every constant carries its source. Nothing else in the project types these numbers again: code
takes them from here (``from micro.materials import FE, FE3O4, PDMS, SEED``).

=========  =================  ================  ==========  ========  ===========  ==========
material   density [kg/m^3]   sigma_s [Am2/kg]  Ms [A/m]    K1 [J/m3]  A [J/m]     E [Pa], nu
=========  =================  ================  ==========  ========  ===========  ==========
Fe         7870               218               1.716e6     4.8e4      2.1e-11     211e9, 0.29
Fe3O4      5170               92                4.76e5      -1.1e4     1.3e-11     --
PDMS       1210 (seed)        --                --          --         --          2e6, 0.45
=========  =================  ================  ==========  ========  ===========  ==========

Named presets (:data:`PARTICLE_PRESETS`, :data:`MATRIX_PRESETS`; each with its sources; the
default everywhere is ``seed-paper``, the numbers above):

================  ==========  ===========  ========  =========  ===========  ==========
particle          rho         sigma_s      radius    gsd        shell        E, nu
================  ==========  ===========  ========  =========  ===========  ==========
seed-paper        7870        178          25 nm     1.4        --           211 GPa, 0.29
nanofer           7870        178 (calib.) 25 nm     1.4        3 nm Fe3O4   211 GPa, 0.29
carbonyl-iron     7800        210          1 um      1.5        --           211 GPa, 0.29
magnetite         5170        92           50 nm     1.4        --           230 GPa, 0.26
================  ==========  ===========  ========  =========  ===========  ==========

================  ==========  =====  =================
matrix            E [MPa]     nu     density [kg/m^3]
================  ==========  =====  =================
seed-paper        2.0         0.45   1210
sylgard184-10to1  2.0         0.49   1030
sylgard184-20to1  1.0         0.49   1030
ecoflex-00-30     0.118       0.49   1070
rtv615            1.96        0.49   1020
================  ==========  =====  =================

Size bounds: without explicit ``r_min``/``r_max`` the lognormal's bounds follow the mean radius
(:func:`radius_bounds_m`: the seed's ratios 0.4 and 2; 25 nm -> [10, 50] nm exactly).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from scipy.constants import mu_0 as MU0

from micro.common.validate import InputError, Range, check_positive, check_range

__all__ = ["ElasticMaterial", "POISSON_RANGE", "Constituent", "FE", "FE3O4", "PDMS", "SeedParameters", "SEED", "GRAVITY_M_S2",
           "mixture_density_kg_m3", "elastic", "ParticlePreset", "MatrixPreset",
           "PARTICLE_PRESETS", "MATRIX_PRESETS", "DEFAULT_PRESET", "particle_preset",
           "matrix_preset", "radius_bounds_m"]

#: Standard acceleration of gravity [m/s^2] (the seed paper's self-weight uses 9.81).
GRAVITY_M_S2 = 9.81


#: Poisson's ratio of an isotropic solid, (-1, 0.5): defined once here and used by
#: ElasticMaterial, the cell's CELL_RANGES["nu"], the study rules and the CLI options.
POISSON_RANGE = Range(-1.0, 0.5, lo_open=True, hi_open=True)


@dataclass(frozen=True)
class ElasticMaterial:
    """Isotropic linear elastic solid: the one material type of every elastic solver.

    Parameters
    ----------
    E_Pa : float -- Young's modulus [Pa], > 0 (default: the seed's PDMS, 2 MPa)
    nu : float -- Poisson's ratio [-], in (-1, 0.5) (default: the seed's PDMS, 0.45)
    density_kg_m3 : float -- mass density [kg/m^3], >= 0 (self-weight only; default: the
        seed's PDMS, 1210)
    """

    E_Pa: float = 2.0e6
    nu: float = 0.45
    density_kg_m3: float = 1210.0

    def __post_init__(self):
        check_positive("E_Pa (Young's modulus)", self.E_Pa, "Pa")
        POISSON_RANGE.check("nu (Poisson's ratio)", self.nu)
        check_positive("density_kg_m3", self.density_kg_m3, "kg/m^3", allow_zero=True)

    @property
    def lame_Pa(self) -> tuple[float, float]:
        """Lame parameters (lambda, mu) [Pa]."""
        E, nu = self.E_Pa, self.nu
        return E * nu / ((1.0 + nu) * (1.0 - 2.0 * nu)), E / (2.0 * (1.0 + nu))

    @property
    def bulk_shear_Pa(self) -> tuple[float, float]:
        """Bulk and shear modulus (K, G) [Pa]."""
        E, nu = self.E_Pa, self.nu
        return E / (3.0 * (1.0 - 2.0 * nu)), E / (2.0 * (1.0 + nu))


@dataclass(frozen=True)
class Constituent:
    """Constants of one constituent material, SI units, with their sources.

    Parameters
    ----------
    name : str
    density_kg_m3 : float -- mass density [kg/m^3]
    E_Pa, nu : float -- Young's modulus [Pa] and Poisson's ratio [-] (nan where not needed)
    sigma_s_Am2_kg : float -- specific saturation moment at 300 K [A m^2/kg] (0: non-magnetic)
    K1_J_m3 : float -- first magnetocrystalline anisotropy constant [J/m^3] (0: none)
    A_J_m : float -- exchange stiffness [J/m] (0: non-magnetic)
    anisotropy : str -- "cubic", "uniaxial" or "none"
    sources : str -- where each number comes from
    """

    name: str
    density_kg_m3: float
    E_Pa: float = math.nan
    nu: float = math.nan
    sigma_s_Am2_kg: float = 0.0
    K1_J_m3: float = 0.0
    A_J_m: float = 0.0
    anisotropy: str = "none"
    sources: str = ""

    def __post_init__(self):
        check_positive("density_kg_m3", self.density_kg_m3, "kg/m^3")
        # iron's 218 A m^2/kg is the largest of any element at room temperature; 300 bounds
        # every real magnetic material with margin
        check_range("sigma_s_Am2_kg", self.sigma_s_Am2_kg, 0.0, 300.0, "A m^2/kg")
        check_range("K1_J_m3", self.K1_J_m3, -1e8, 1e8, "J/m^3")
        check_range("A_J_m", self.A_J_m, 0.0, 1e-9, "J/m")
        if not math.isnan(self.E_Pa):
            check_positive("E_Pa", self.E_Pa, "Pa")
        if not math.isnan(self.nu):
            check_range("nu", self.nu, -1.0, 0.5, "", lo_open=True, hi_open=True)
        if self.anisotropy not in ("cubic", "uniaxial", "none"):
            raise InputError(f"anisotropy must be one of cubic, uniaxial, none; got "
                             f"{self.anisotropy!r}")

    @property
    def Ms_A_m(self) -> float:
        """Saturation magnetization ``rho sigma_s`` [A/m]."""
        return self.density_kg_m3 * self.sigma_s_Am2_kg

    @property
    def exchange_length_m(self) -> float:
        """Magnetostatic exchange length ``sqrt(2 A / (mu0 Ms^2))`` [m] (nan if non-magnetic)."""
        if self.Ms_A_m <= 0:
            return math.nan
        return math.sqrt(2.0 * self.A_J_m / (MU0 * self.Ms_A_m ** 2))


#: alpha-iron at room temperature.
FE = Constituent(
    name="Fe", density_kg_m3=7870.0, E_Pa=211e9, nu=0.29, sigma_s_Am2_kg=218.0,
    K1_J_m3=4.8e4, A_J_m=2.1e-11, anisotropy="cubic",
    sources="density: CRC Handbook of Chemistry and Physics (97th ed., 2016), 7.874 g/cm^3, "
            "7870 as in the seed paper; sigma_s: Crangle & Goodman, Proc. R. Soc. Lond. A 321 "
            "(1971) 477, 217.6 A m^2/kg at 293 K (Cullity & Graham, Introduction to Magnetic "
            "Materials, 2nd ed. 2009, Table 4.2: 218 emu/g); K1: Cullity & Graham Table 7.4, "
            "4.8e4 J/m^3 at room temperature; A: Coey, Magnetism and Magnetic Materials (CUP "
            "2010) Table 7.1, 2.1e-11 J/m; E, nu: polycrystalline iron, ASM Handbook vol. 2 / "
            "Kaye & Laby, 211 GPa and 0.29.")

#: magnetite, the oxide shell of the seed's NANOFER particles.
FE3O4 = Constituent(
    name="Fe3O4", density_kg_m3=5170.0, sigma_s_Am2_kg=92.0, K1_J_m3=-1.1e4, A_J_m=1.3e-11,
    anisotropy="cubic",
    sources="density: Cornell & Schwertmann, The Iron Oxides, 2nd ed. (Wiley-VCH 2003) Table "
            "2.1, 5.18 g/cm^3 (CRC 5.17); sigma_s: Cornell & Schwertmann Table 6.1, 92-100 A "
            "m^2/kg (Cullity & Graham Table 4.2: 92); K1: Cullity & Graham Table 7.4, -1.1e4 "
            "J/m^3; A: Heider & Williams, Geophys. Res. Lett. 15 (1988) 184, 1.32e-11 J/m.")

#: the seed paper's PDMS (Gusenbauer et al. 2013, Table 1).
PDMS = Constituent(
    name="PDMS", density_kg_m3=1210.0, E_Pa=2.0e6, nu=0.45,
    sources="seed paper (Gusenbauer et al., EPJ Web of Conferences 40, 02001 (2013)) Table 1: "
            "1210 kg/m^3, 2 MPa, 0.45.")


@dataclass(frozen=True)
class SeedParameters:
    """The seed paper's parameters (Table 1 and Section 3.1), SI units."""

    c: float = 0.035                      # particle concentration in the polymer [-]
    d: float = 0.5                        # guessed powder packing density [-]
    radius_m: float = 25e-9               # mean particle radius [m]
    sigma_s_Am2_kg: float = 178.0         # specific saturation moment of the powder [A m^2/kg]
    particle_density_kg_m3: float = FE.density_kg_m3
    gradB_T_per_m: float = 1.78           # field gradient [T/m] (electromagnet at 1.5 A)
    current_A: float = 1.5                # coil current giving that gradient [A]
    E_Pa: float = PDMS.E_Pa
    nu: float = PDMS.nu
    pdms_density_kg_m3: float = PDMS.density_kg_m3
    paper_body_force_N_m3: float = 43.79e3   # printed in the paper
    abaqus_force_N_m3: float = 40e3          # force giving 4 mm in Abaqus
    elmer_force_N_m3: float = 50e3           # force giving 4 mm in Elmer
    deflection_m: float = 4e-3               # measured tip deflection of the cantilever [m]
    gsd: float = 1.4                         # geometric standard deviation of the radii [-]
    r_min_m: float = 10e-9                   # smallest radius of the truncated lognormal [m]
    r_max_m: float = 50e-9                   # largest radius [m]

    @property
    def Ms_A_m(self) -> float:
        """Saturation magnetization of the seed's particles, ``rho sigma_s`` [A/m]."""
        return self.particle_density_kg_m3 * self.sigma_s_Am2_kg


#: The seed paper's parameters. sigma_s = 178 A m^2/kg is the NANOFER powder's specific moment
#: (an Fe core with an oxide shell, mass-averaged), not bulk iron's 218.
SEED = SeedParameters()


def mixture_density_kg_m3(phi: float, matrix: Constituent = PDMS,
                          particle: Constituent = FE) -> float:
    """Density of the composite ``(1 - phi) rho_m + phi rho_p`` [kg/m^3]."""
    return (1.0 - phi) * matrix.density_kg_m3 + phi * particle.density_kg_m3


def elastic(c: Constituent) -> ElasticMaterial:
    """The elastic material of a constituent (its E, nu and density)."""
    return ElasticMaterial(c.E_Pa, c.nu, c.density_kg_m3)


# --------------------------------------------------------------------------- named presets
#: The preset every command and study uses unless told otherwise: the seed paper's numbers
#: (so that ``make run`` and every committed result stay as they are).
DEFAULT_PRESET = "seed-paper"


def radius_bounds_m(mean_radius_m: float) -> tuple[float, float]:
    """Bounds ``(r_min, r_max)`` [m] of the truncated lognormal that follow a mean (or median)
    radius ``r`` when none are given: the seed's ratios, ``r_min = 0.4 r`` and ``r_max = 2 r``.

    Computed as ``SEED.r_min_m * (r / SEED.radius_m)`` so that the seed's own 25 nm gives its
    [10, 50] nm bit for bit (the factor is exactly 1.0); 1 um gives [0.4, 2] um.
    """
    k = float(mean_radius_m) / SEED.radius_m
    return SEED.r_min_m * k, SEED.r_max_m * k


@dataclass(frozen=True)
class ParticlePreset:
    """A filler powder by name: what the particle options of ``mapsim`` and the particle keys of
    a study default to (explicit options and keys win).

    Parameters
    ----------
    name : str
    density_kg_m3 : float -- density of the particle (core) material [kg/m^3]
    powder_sigma_Am2_kg : float -- mass-averaged specific saturation moment of the powder
        [A m^2/kg]: the reference material of ``phi_eff`` in :mod:`micro.dipoles`
    core_sigma_Am2_kg : float or None -- specific moment of the core [A m^2/kg]; None keeps
        :class:`micro.particles.CoreShell`'s rule (the seed's 178 without a shell, Fe's 218
        with one, or the calibrated value with ``calibrate_sigma_Am2_kg``)
    E_Pa, nu : float -- elastic constants of the particles (cell FEM)
    mean_radius_m, gsd : float -- truncated lognormal of the outer radius (bounds:
        :func:`radius_bounds_m`)
    shell_m : float -- Fe3O4 shell thickness [m] (0: homogeneous particles)
    calibrate_sigma_Am2_kg : float or None -- calibrate the core moment to this powder average
    core : Constituent -- core material of the intrinsic magnetization laws (regime, approach)
    sources : str -- where each number comes from
    """

    name: str
    density_kg_m3: float
    powder_sigma_Am2_kg: float
    core_sigma_Am2_kg: float | None
    E_Pa: float
    nu: float
    mean_radius_m: float
    gsd: float
    shell_m: float = 0.0
    calibrate_sigma_Am2_kg: float | None = None
    core: Constituent = FE
    sources: str = ""

    def __post_init__(self):
        check_range("density_kg_m3", self.density_kg_m3, 1e3, 3e4, "kg/m^3")
        check_range("powder_sigma_Am2_kg", self.powder_sigma_Am2_kg, 0.0, 300.0, "A m^2/kg",
                    lo_open=True)
        if self.core_sigma_Am2_kg is not None:
            check_range("core_sigma_Am2_kg", self.core_sigma_Am2_kg, 0.0, 300.0, "A m^2/kg",
                        lo_open=True)
        check_positive("E_Pa", self.E_Pa, "Pa")
        check_range("nu", self.nu, -1.0, 0.5, "", lo_open=True, hi_open=True)
        check_range("mean_radius_m", self.mean_radius_m, 1e-10, 1e-3, "m")
        check_range("gsd", self.gsd, 1.0, 10.0, "", lo_open=True)
        if not 0.0 <= self.shell_m < self.radius_bounds_m[0]:
            raise InputError(f"shell_m {self.shell_m:g} m must be in [0, r_min = "
                             f"{self.radius_bounds_m[0]:g} m)")

    @property
    def radius_bounds_m(self) -> tuple[float, float]:
        """``(r_min, r_max)`` [m] of the lognormal (:func:`radius_bounds_m` of the mean)."""
        return radius_bounds_m(self.mean_radius_m)

    @property
    def Ms_A_m(self) -> float:
        """Saturation magnetization of the powder material ``rho sigma_powder`` [A/m]."""
        return self.density_kg_m3 * self.powder_sigma_Am2_kg


@dataclass(frozen=True)
class MatrixPreset:
    """An elastomer matrix by name: E, nu and density of the matrix (explicit options win)."""

    name: str
    E_Pa: float
    nu: float
    density_kg_m3: float
    sources: str = ""

    def __post_init__(self):
        ElasticMaterial(self.E_Pa, self.nu, self.density_kg_m3)       # the same checks
        check_range("density_kg_m3", self.density_kg_m3, 500.0, 3000.0, "kg/m^3")

    @property
    def elastic(self) -> ElasticMaterial:
        return ElasticMaterial(self.E_Pa, self.nu, self.density_kg_m3)


_SEED_SOURCE = ("seed paper (Gusenbauer et al., EPJ Web of Conferences 40, 02001 (2013)) "
                "Table 1 and Sec. 3.1")

#: Filler powders. Values marked "typical" are literature values within a spread of
#: powders and measurements, not one datasheet's guarantee: give --core-sigma, --mean-radius
#: etc. (or study keys) for a measured powder.
PARTICLE_PRESETS = {p.name: p for p in (
    ParticlePreset(
        name="seed-paper", density_kg_m3=SEED.particle_density_kg_m3,
        powder_sigma_Am2_kg=SEED.sigma_s_Am2_kg, core_sigma_Am2_kg=None, E_Pa=FE.E_Pa,
        nu=FE.nu, mean_radius_m=SEED.radius_m, gsd=SEED.gsd,
        sources=f"{_SEED_SOURCE}: homogeneous spheres of iron's density 7870 kg/m^3 with the "
                "powder's measured 178 A m^2/kg, mean radius 25 nm; the lognormal's gsd 1.4 "
                "and bounds [10, 50] nm are this project's reading of the seed's nanopowder "
                "(homogenize/studies/default_study.toml); E, nu: Fe (FE)."),
    ParticlePreset(
        name="nanofer", density_kg_m3=FE.density_kg_m3, powder_sigma_Am2_kg=178.0,
        core_sigma_Am2_kg=None, E_Pa=FE.E_Pa, nu=FE.nu, mean_radius_m=25e-9, gsd=1.4,
        shell_m=3e-9, calibrate_sigma_Am2_kg=178.0,
        sources="NANOFER-type Fe/Fe3O4 nanopowder (NANO IRON s.r.o. NANOFER 25/STAR product "
                "sheets: zero-valent iron, d50 < 50 nm, surface-stabilized by a thin iron "
                "oxide layer): the seed's powder as core-shell particles. 178 A m^2/kg: the "
                f"{_SEED_SOURCE} measured moment, to which the Fe core's moment is calibrated "
                "(199 A m^2/kg under the shell, below iron's 218, as the carbon of an "
                "Fe/Fe3O4-C powder suggests); shell 3 nm Fe3O4: typical literature value for "
                "nanoscale zero-valent iron (oxide shells of 2-4 nm, e.g. Nurmi et "
                "al., Environ. Sci. Technol. 39 (2005) 1221); size as seed-paper."),
    ParticlePreset(
        name="carbonyl-iron", density_kg_m3=7800.0, powder_sigma_Am2_kg=210.0,
        core_sigma_Am2_kg=210.0, E_Pa=FE.E_Pa, nu=FE.nu, mean_radius_m=1e-6, gsd=1.5,
        sources="carbonyl iron powder (spherical, >= 97.5 wt% Fe with C, N, O; BASF CIP "
                "grades). Density 7800 kg/m^3: typical datasheet value (7.8 g/cm^3, below "
                "iron's 7.87 by the C, N, O content); 210 A m^2/kg: typical literature value "
                "of measured CIP saturation (195-215 A m^2/kg; 97.5 % of iron's 218 is 213); "
                "mean radius 1 um (d50 ~ 2 um of the fine grades), gsd 1.5: typical; E, nu: "
                "Fe (FE)."),
    ParticlePreset(
        name="magnetite", density_kg_m3=FE3O4.density_kg_m3,
        powder_sigma_Am2_kg=FE3O4.sigma_s_Am2_kg, core_sigma_Am2_kg=FE3O4.sigma_s_Am2_kg,
        E_Pa=230e9, nu=0.26, mean_radius_m=50e-9, gsd=1.4, core=FE3O4,
        sources="Fe3O4 powder: density, sigma_s, K1, A of bulk magnetite (FE3O4; nanopowders "
                "often measure 60-90 A m^2/kg: give --core-sigma); mean radius 50 nm: typical "
                "of commercial magnetite nanopowders (50-100 nm diameter); E 230 GPa, nu 0.26: "
                "Hill average of typical single-crystal constants c11 = 272, c12 = 108, "
                "c44 = 97 GPa (typical literature values)."),
)}

#: Elastomer matrices. Silicone moduli depend on the mixing ratio, cure time and temperature and
#: on the test: a spread of 2x is usual for the same nominal recipe (Varner & Cohen,
#: arXiv:2404.16960 (2024)); give --matrix-E for a measured one.
MATRIX_PRESETS = {m.name: m for m in (
    MatrixPreset(name="seed-paper", E_Pa=PDMS.E_Pa, nu=PDMS.nu, density_kg_m3=PDMS.density_kg_m3,
                 sources=PDMS.sources),
    MatrixPreset(
        name="sylgard184-10to1", E_Pa=2.0e6, nu=0.49, density_kg_m3=1030.0,
        sources="Dow SYLGARD 184 technical data sheet: specific gravity 1.03 (cured), mixing "
                "ratio 10:1 base:curing agent; E: Wang, Volinsky & Gallant, J. Appl. Polym. "
                "Sci. 131 (2014) 41050 (E ~ 20 MPa / mixing ratio, 0.57-3.7 MPa from 33:1 to "
                "5:1), 2.0 MPa at 10:1; Johnston et al., J. Micromech. Microeng. 24 (2014) "
                "035017 measured 1.3-3.0 MPa at 10:1 for cure temperatures 25-200 C; nu 0.49: "
                "typical (nearly incompressible rubber)."),
    MatrixPreset(
        name="sylgard184-20to1", E_Pa=1.0e6, nu=0.49, density_kg_m3=1030.0,
        sources="SYLGARD 184 at 20:1: E from Wang, Volinsky & Gallant (2014) (20 MPa / 20 = "
                "1.0 MPa; other reports down to ~0.6 MPa); density as 10:1 (typical: the "
                "ratio moves it by < 1 %); nu 0.49: typical."),
    MatrixPreset(
        name="ecoflex-00-30", E_Pa=0.118e6, nu=0.49, density_kg_m3=1070.0,
        sources="Smooth-On Ecoflex 00-30 technical bulletin: specific gravity 1.07 g/cc, 100 % "
                "modulus 10 psi (69 kPa); E = 3 x 69 kPa / (2 - 1/4) = 0.118 MPa from that "
                "secant stress with a neo-Hookean fit (typical literature values 0.05-0.13 "
                "MPa); nu 0.49: typical."),
    MatrixPreset(
        name="rtv615", E_Pa=1.96e6, nu=0.49, density_kg_m3=1020.0,
        sources="Momentive RTV615 data sheet (10:1): specific gravity 1.02, hardness Shore A "
                "44; E = 1.96 MPa from Shore A 44 by Gent's relation (Gent, Trans. Inst. Rubber "
                "Ind. 34 (1958) 46) -- an estimate, typical of reported 1.4-2 MPa; nu 0.49: "
                "typical."),
)}


def _preset(kind: str, table: dict, name):
    if isinstance(name, (ParticlePreset, MatrixPreset)):
        return name
    if not isinstance(name, str) or name not in table:
        raise InputError(f"{kind} material must be one of {', '.join(table)}; got {name!r}")
    return table[name]


def particle_preset(name: str = DEFAULT_PRESET) -> ParticlePreset:
    """The particle preset ``name`` (one of :data:`PARTICLE_PRESETS`)."""
    return _preset("particle", PARTICLE_PRESETS, name)


def matrix_preset(name: str = DEFAULT_PRESET) -> MatrixPreset:
    """The matrix preset ``name`` (one of :data:`MATRIX_PRESETS`)."""
    return _preset("matrix", MATRIX_PRESETS, name)
