"""Closed-form effective moduli of particle-filled isotropic composites.

All take the particle volume fraction ``phi`` [1] (scalar or array) and the bulk and shear moduli
[Pa] of matrix (``K_m, G_m``) and particles (``K_p, G_p``); the results are in Pa.

* Hashin-Shtrikman bounds (Walpole's form, valid also for ill-ordered phases),
* Eshelby's dilute estimate (non-interacting spheres, first order in phi),
* Mori-Tanaka (equals the HS bound on the side of the matrix for spheres),
* Guth-Gold for rigid spheres in a rubber: ``E = E_m (1 + 2.5 phi + 14.1 phi^2)``.
"""
from __future__ import annotations

import numpy as np

__all__ = ["lame", "bulk_shear", "young_poisson", "hashin_shtrikman_bounds", "eshelby_dilute",
           "mori_tanaka", "guth_gold", "isotropic_stiffness_voigt"]


def lame(E_Pa, nu):
    """Lame parameters (lambda, mu) [Pa] from Young's modulus and Poisson's ratio."""
    return E_Pa * nu / ((1.0 + nu) * (1.0 - 2.0 * nu)), E_Pa / (2.0 * (1.0 + nu))


def bulk_shear(E_Pa, nu):
    """Bulk and shear modulus (K, G) [Pa]."""
    return E_Pa / (3.0 * (1.0 - 2.0 * nu)), E_Pa / (2.0 * (1.0 + nu))


def young_poisson(K_Pa, G_Pa):
    """Young's modulus [Pa] and Poisson's ratio from (K, G)."""
    return 9.0 * K_Pa * G_Pa / (3.0 * K_Pa + G_Pa), (3.0 * K_Pa - 2.0 * G_Pa) / (2.0 * (3.0 * K_Pa + G_Pa))


def isotropic_stiffness_voigt(E_Pa: float, nu: float) -> np.ndarray:
    """6 x 6 Voigt stiffness [Pa] of an isotropic material (engineering shear strains)."""
    lam, mu = lame(E_Pa, nu)
    C = np.zeros((6, 6))
    C[:3, :3] = lam
    C[np.arange(3), np.arange(3)] += 2.0 * mu
    C[np.arange(3, 6), np.arange(3, 6)] = mu
    return C


def _zeta(K, G):
    return G / 6.0 * (9.0 * K + 8.0 * G) / (K + 2.0 * G)


def hashin_shtrikman_bounds(phi, K_m, G_m, K_p, G_p) -> dict:
    """Hashin-Shtrikman bounds on the effective bulk and shear modulus of a two-phase composite.

    Returns dict with ``K_lower_Pa, K_upper_Pa, G_lower_Pa, G_upper_Pa`` (and the Young's modulus
    ``E_lower_Pa, E_upper_Pa`` from the pair of lower / upper bounds, which bound E since E is
    increasing in K and G).
    """
    phi = np.asarray(phi, dtype=float)
    f = (1.0 - phi, phi)
    Ks, Gs = (K_m, K_p), (G_m, G_p)

    def kb(Gref):
        return 1.0 / (f[0] / (Ks[0] + 4.0 / 3.0 * Gref) + f[1] / (Ks[1] + 4.0 / 3.0 * Gref)) - 4.0 / 3.0 * Gref

    def gb(z):
        return 1.0 / (f[0] / (Gs[0] + z) + f[1] / (Gs[1] + z)) - z

    out = {
        "K_lower_Pa": kb(min(Gs)), "K_upper_Pa": kb(max(Gs)),
        "G_lower_Pa": gb(_zeta(min(Ks), min(Gs))), "G_upper_Pa": gb(_zeta(max(Ks), max(Gs))),
    }
    out["E_lower_Pa"] = young_poisson(out["K_lower_Pa"], out["G_lower_Pa"])[0]
    out["E_upper_Pa"] = young_poisson(out["K_upper_Pa"], out["G_upper_Pa"])[0]
    return out


def _concentration(K_m, G_m, K_p, G_p):
    alpha = 3.0 * K_m / (3.0 * K_m + 4.0 * G_m)
    beta = 6.0 * (K_m + 2.0 * G_m) / (5.0 * (3.0 * K_m + 4.0 * G_m))
    # Eshelby strain concentration of a sphere (bulk, shear)
    aK = 1.0 / (1.0 + alpha * (K_p - K_m) / K_m)
    aG = 1.0 / (1.0 + beta * (G_p - G_m) / G_m)
    return aK, aG


def eshelby_dilute(phi, K_m, G_m, K_p, G_p) -> tuple:
    """Dilute (non-interacting) spheres: (K_eff, G_eff) [Pa], exact to first order in phi."""
    aK, aG = _concentration(K_m, G_m, K_p, G_p)
    phi = np.asarray(phi, dtype=float)
    return K_m + phi * (K_p - K_m) * aK, G_m + phi * (G_p - G_m) * aG


def mori_tanaka(phi, K_m, G_m, K_p, G_p) -> tuple:
    """Mori-Tanaka estimate for spheres: (K_eff, G_eff) [Pa]."""
    aK, aG = _concentration(K_m, G_m, K_p, G_p)
    phi = np.asarray(phi, dtype=float)
    return (K_m + phi * (K_p - K_m) * aK / (1.0 - phi + phi * aK),
            G_m + phi * (G_p - G_m) * aG / (1.0 - phi + phi * aG))


def guth_gold(phi, E_m_Pa):
    """Guth-Gold: Young's modulus of a rubber with rigid spheres, ``E_m (1 + 2.5 phi + 14.1 phi^2)``."""
    phi = np.asarray(phi, dtype=float)
    return E_m_Pa * (1.0 + 2.5 * phi + 14.1 * phi ** 2)
