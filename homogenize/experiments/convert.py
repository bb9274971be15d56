"""Converters from the two outside data sets' own formats to the spec's TOML + CSV.

Both are documented in ``examples/data/PROVENANCE.md``; the tests re-run them on the raw
copies in ``examples/data/raw/`` and compare with the committed spec files.
"""
from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from micro.common.validate import InputError

from micro.materials import FE

from homogenize.experiments.io import Matrix, Particles, write_experiment

__all__ = ["read_diguet", "read_rtv615", "write_diguet", "write_rtv615", "DIGUET_PHI"]

#: Iron volume fraction of the Diguet et al. (2010) sample: composite density 2833 kg/m^3
#: (Stewart & Anand 2025) = (1 - phi) 1050 + phi 7870 kg/m^3 (silicone about 1050 kg/m^3).
DIGUET_PHI = round((2833.0 - 1050.0) / (FE.density_kg_m3 - 1050.0), 3)


def read_diguet(path) -> dict:
    """The digitised curve: 17 rows 'mu0 H [T], strain [-]', no header; rows 1-9 rise,
    rows 10-17 fall. Returns spec columns."""
    path = Path(path)
    rows = [r for r in csv.reader(path.read_text().splitlines()) if r]
    if len(rows) != 17:
        raise InputError(f"{path}: expected the 17 rows of the Diguet curve, got {len(rows)}")
    vals = []
    for i, r in enumerate(rows, start=1):
        try:
            vals.append((float(r[0]), float(r[1])))
        except (ValueError, IndexError):
            raise InputError(f"{path}, row {i}: expected two numbers 'B_T, strain'") from None
    a = np.array(vals)
    n = len(a)
    return {"specimen": ["diguet2010"] * n, "phi": [DIGUET_PHI] * n, "aspect_ratio": [0.80] * n,
            "B_T": list(a[:, 0]), "strain": list(a[:, 1]),
            "radius_mean_m": [2.0e-6] * n,
            "branch": ["up"] * 9 + ["down"] * (n - 9)}


def read_rtv615(path) -> dict:
    """The Instron export: ';'-separated, 17 metadata lines, then a header and rows of
    Time (s); True Strain; True Stress (MPa); Engineering Strain; Engineering Stress (MPa).
    Returns spec columns (engineering strain, engineering stress in Pa)."""
    path = Path(path)
    lines = path.read_text(encoding="utf-8-sig").splitlines()
    header_at = next((i for i, l in enumerate(lines) if l.startswith("Time (s)")), None)
    if header_at is None or header_at != 17:
        raise InputError(f"{path}: expected 17 metadata lines and then the 'Time (s);...' header")
    strain, stress = [], []
    for k, l in enumerate(lines[header_at + 1:], start=header_at + 2):
        if not l.strip():
            continue
        f = l.split(";")
        try:
            strain.append(float(f[3]))
            stress.append(float(f[4]) * 1e6)           # MPa -> Pa
        except (ValueError, IndexError):
            raise InputError(f"{path}, row {k}: columns 4-5 (engineering strain, stress) "
                             "must be numbers") from None
    n = len(strain)
    return {"specimen": ["RTV615"] * n, "phi": [0.0] * n, "strain": strain, "stress_Pa": stress}


def write_diguet(raw, toml_path) -> None:
    cols = read_diguet(raw)
    # matrix: E0 = 0.14 MPa, the silicone matrix's modulus that Diguet's thesis reports
    # (theses.fr 2010GRENY002, abstract), nearly incompressible; NOT the 690 kPa = 3 x 230 kPa
    # that Stewart & Anand 2025 fitted to this curve (a fitted value is never an input)
    write_experiment(toml_path, "magnetostriction", cols,
                     title="Diguet et al. 2010, soft MRE cylinder L/D = 0.80, axial strain",
                     matrix=Matrix(E_Pa=140e3, nu=0.499, density_kg_m3=1050.0),
                     particles=Particles(density_kg_m3=FE.density_kg_m3,
                                         sigma_s_Am2_kg=FE.sigma_s_Am2_kg,
                                         radius_mean_m=2.0e-6, radius_min_m=0.5e-6,
                                         radius_max_m=5.0e-6))


def write_rtv615(raw, toml_path) -> None:
    cols = read_rtv615(raw)
    write_experiment(toml_path, "tensile", cols,
                     title="Momentive RTV615 PDMS, ASTM D412 pull to failure (SYMME lab)",
                     matrix=Matrix(E_Pa=1.0e6, nu=0.49, density_kg_m3=1020.0))
