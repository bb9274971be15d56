"""Exporters of homogenized parameters to external macro solvers, and parsers that read them back.

* Elmer (StressSolver): a ``Material`` section (``Youngs Modulus``, ``Poisson Ratio``,
  ``Density``) and a ``Body Force`` section with ``Stress Bodyforce 1..3`` -- force per volume
  [N/m^3]. Elmer has no separate gravity load for this solver, so self-weight (if asked for) is
  added to the body force and both parts are named in comments.
* Abaqus (input-file keywords): ``*MATERIAL`` with ``*ELASTIC`` (E, nu) and ``*DENSITY``, and a
  ``*DLOAD`` with the body-force labels ``BX/BY/BZ`` [N/m^3] on an element set, plus an optional
  ``GRAV`` line (magnitude [m/s^2] and direction) for the self-weight.

Everything is SI. :func:`parse_elmer` and :func:`parse_abaqus` return an :class:`ExportSpec`-like
dict of the numbers, so a round trip is checkable.
"""
from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from micro._validate import InputError, check_choice, check_positive, check_range

__all__ = ["ExportSpec", "DIRECTIONS", "to_elmer", "to_abaqus", "parse_elmer", "parse_abaqus",
           "export_text"]

#: allowed force directions (unit vectors along the global axes)
DIRECTIONS = {"+x": (1, 0, 0), "-x": (-1, 0, 0), "+y": (0, 1, 0), "-y": (0, -1, 0),
              "+z": (0, 0, 1), "-z": (0, 0, -1)}


@dataclass(frozen=True)
class ExportSpec:
    """What is exported.

    body_force_N_m3 : magnitude of the magnetic body force [N/m^3], >= 0
    E_Pa : Young's modulus [Pa]; nu : Poisson ratio in (-1, 0.5); density_kg_m3 : [kg/m^3]
    direction : one of :data:`DIRECTIONS` -- direction of the body force (and of gravity)
    gravity_m_s2 : self-weight acceleration [m/s^2], 0 for none
    name : material name; elset : Abaqus element set; index : Elmer section number
    """
    body_force_N_m3: float
    E_Pa: float
    nu: float
    density_kg_m3: float
    direction: str = "-z"
    gravity_m_s2: float = 0.0
    name: str = "MAP_PDMS"
    elset: str = "EALL"
    index: int = 1

    def __post_init__(self):
        check_positive("body_force_N_m3", self.body_force_N_m3, "N/m^3", allow_zero=True)
        check_positive("E_Pa", self.E_Pa, "Pa")
        check_range("nu", self.nu, -1.0, 0.5, "", lo_open=True, hi_open=True)
        check_positive("density_kg_m3", self.density_kg_m3, "kg/m^3", allow_zero=True)
        check_choice("direction", self.direction, tuple(DIRECTIONS))
        check_positive("gravity_m_s2", self.gravity_m_s2, "m/s^2", allow_zero=True)
        if not re.fullmatch(r"[A-Za-z][A-Za-z0-9_\-]*", self.name):
            raise InputError(f"name must start with a letter and contain only letters, digits, "
                             f"'_' or '-', got {self.name!r}")
        if not re.fullmatch(r"[A-Za-z][A-Za-z0-9_\-]*", self.elset):
            raise InputError(f"elset must be an Abaqus set name (letters, digits, '_', '-'), "
                             f"got {self.elset!r}")
        check_positive("index", self.index, "")

    @property
    def unit(self) -> np.ndarray:
        return np.array(DIRECTIONS[self.direction], float)


def _g(x: float) -> str:
    return repr(float(x))  # shortest exact round-trip representation


def to_elmer(spec: ExportSpec) -> str:
    """Elmer ``.sif`` Material and Body Force sections for ``spec``."""
    weight = spec.density_kg_m3 * spec.gravity_m_s2
    total = (spec.body_force_N_m3 + weight) * spec.unit
    lines = [
        "! mapsim export for Elmer StressSolver (SI units: Pa, kg/m^3, N/m^3)",
        f"! magnetic body force {_g(spec.body_force_N_m3)} N/m^3 along {spec.direction}"
        + (f", plus self-weight density*g = {_g(weight)} N/m^3" if weight else ""),
        f"Material {spec.index}",
        f'  Name = "{spec.name}"',
        f"  Youngs Modulus = Real {_g(spec.E_Pa)}",
        f"  Poisson Ratio = Real {_g(spec.nu)}",
        f"  Density = Real {_g(spec.density_kg_m3)}",
        "End",
        "",
        f"Body Force {spec.index}",
        f'  Name = "{spec.name}_magnetic"',
    ]
    lines += [f"  Stress Bodyforce {i + 1} = Real {_g(total[i] + 0.0)}" for i in range(3)]
    lines += ["End", ""]
    return "\n".join(lines)


def to_abaqus(spec: ExportSpec) -> str:
    """Abaqus ``*MATERIAL`` block and ``*DLOAD`` body-force (and gravity) lines for ``spec``."""
    u = spec.unit
    axis = "XYZ"[int(np.argmax(np.abs(u)))]
    lines = [
        "** mapsim export for Abaqus (SI units: Pa, kg/m^3, N/m^3, m/s^2)",
        f"*MATERIAL, NAME={spec.name}",
        "*ELASTIC",
        f"{_g(spec.E_Pa)}, {_g(spec.nu)}",
        "*DENSITY",
        f"{_g(spec.density_kg_m3)},",
        "** in the load step: magnetic body force per volume",
        "*DLOAD",
        f"{spec.elset}, B{axis}, {_g(spec.body_force_N_m3 * u.sum())}",
    ]
    if spec.gravity_m_s2 > 0:
        lines.append(f"{spec.elset}, GRAV, {_g(spec.gravity_m_s2)}, "
                     + ", ".join(_g(c + 0.0) for c in u))
    return "\n".join(lines) + "\n"


def export_text(spec: ExportSpec, to: str) -> str:
    """``to_elmer`` or ``to_abaqus`` by name ("elmer" | "abaqus")."""
    check_choice("to", to, ("elmer", "abaqus"))
    return to_elmer(spec) if to == "elmer" else to_abaqus(spec)


_NUM = r"([-+0-9.eEinfa]+)"


def _num(text: str, pattern: str, what: str) -> float:
    m = re.search(pattern, text, flags=re.IGNORECASE | re.MULTILINE)
    if not m:
        raise InputError(f"{what} not found in the exported text")
    return float(m.group(1))


def parse_elmer(text: str) -> dict:
    """Numbers of an Elmer snippet written by :func:`to_elmer`.

    Returns {E_Pa, nu, density_kg_m3, body_force_N_m3 (3,)} -- the total body force vector.
    """
    E = _num(text, r"^\s*Youngs Modulus\s*=\s*(?:Real\s+)?" + _NUM, "Youngs Modulus")
    nu = _num(text, r"^\s*Poisson Ratio\s*=\s*(?:Real\s+)?" + _NUM, "Poisson Ratio")
    rho = _num(text, r"^\s*Density\s*=\s*(?:Real\s+)?" + _NUM, "Density")
    f = np.zeros(3)
    for i in range(3):
        pat = rf"^\s*Stress Bodyforce {i + 1}\s*=\s*(?:Real\s+)?" + _NUM
        if re.search(pat, text, flags=re.IGNORECASE | re.MULTILINE):
            f[i] = _num(text, pat, f"Stress Bodyforce {i + 1}")
    return {"E_Pa": E, "nu": nu, "density_kg_m3": rho, "body_force_N_m3": f}


def parse_abaqus(text: str) -> dict:
    """Numbers of an Abaqus snippet written by :func:`to_abaqus`.

    Returns {E_Pa, nu, density_kg_m3, body_force_N_m3 (3,), gravity_m_s2, gravity_direction (3,)}.
    """
    m = re.search(r"^\*ELASTIC[^\n]*\n\s*" + _NUM + r"\s*,\s*" + _NUM, text,
                  flags=re.IGNORECASE | re.MULTILINE)
    if not m:
        raise InputError("*ELASTIC data line not found in the exported text")
    E, nu = float(m.group(1)), float(m.group(2))
    rho = _num(text, r"^\*DENSITY[^\n]*\n\s*" + _NUM, "*DENSITY data line")
    f = np.zeros(3)
    for k, axis in enumerate("XYZ"):
        pat = rf"^[^*\n][^,\n]*,\s*B{axis}\s*,\s*" + _NUM
        if re.search(pat, text, flags=re.IGNORECASE | re.MULTILINE):
            f[k] = _num(text, pat, f"B{axis} load")
    grav = re.search(r"^[^*\n][^,\n]*,\s*GRAV\s*,\s*" + ",\\s*".join([_NUM] * 4), text,
                     flags=re.IGNORECASE | re.MULTILINE)
    g = float(grav.group(1)) if grav else 0.0
    gdir = np.array([float(grav.group(i)) for i in (2, 3, 4)]) if grav else np.zeros(3)
    return {"E_Pa": E, "nu": nu, "density_kg_m3": rho, "body_force_N_m3": f,
            "gravity_m_s2": g, "gravity_direction": gdir}
