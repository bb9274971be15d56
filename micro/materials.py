"""The one source of material constants: Fe, Fe3O4, PDMS and the seed paper's parameters.

Every constant carries its source. Nothing else in the project types these numbers again: code
takes them from here (``from micro.materials import FE, FE3O4, PDMS, SEED``).

=========  =================  ================  ==========  ========  ===========  ==========
material   density [kg/m^3]   sigma_s [Am2/kg]  Ms [A/m]    K1 [J/m3]  A [J/m]     E [Pa], nu
=========  =================  ================  ==========  ========  ===========  ==========
Fe         7870               218               1.716e6     4.8e4      2.1e-11     211e9, 0.29
Fe3O4      5170               92                4.76e5      -1.1e4     1.3e-11     --
PDMS       1210 (seed)        --                --          --         --          2e6, 0.45
=========  =================  ================  ==========  ========  ===========  ==========
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from scipy.constants import mu_0 as MU0

from ._validate import InputError, check_positive, check_range

__all__ = ["ElasticMaterial", "Constituent", "FE", "FE3O4", "PDMS", "SeedParameters", "SEED", "GRAVITY_M_S2",
           "mixture_density_kg_m3", "elastic"]

#: Standard acceleration of gravity [m/s^2] (the seed paper's self-weight uses 9.81).
GRAVITY_M_S2 = 9.81


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
        check_range("nu (Poisson's ratio)", self.nu, -1.0, 0.5, "", lo_open=True, hi_open=True)
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
