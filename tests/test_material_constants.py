"""micro.materials is the only place with material numbers (issue 33, item 3): the library
(micro/, homogenize/) refers to FE, FE3O4, PDMS, SEED and GRAVITY_M_S2 instead of retyping their
values, and takes physical constants from scipy.constants. Numbers in docstrings and comments
are prose and not checked; code literals are."""
from __future__ import annotations

import ast
import re
from pathlib import Path

from micro.materials import FE, FE3O4, GRAVITY_M_S2, PDMS, SEED

ROOT = Path(__file__).resolve().parents[1]
OWNER = "micro/materials.py"

#: value -> what it is; a code literal of this value outside micro/materials.py is a retyped
#: material number (the constants themselves, so that the test follows micro.materials)
STRAY = {
    FE.density_kg_m3: "Fe density (FE.density_kg_m3)",
    7874.0: "Fe density, CRC value (FE.density_kg_m3)",
    FE.E_Pa: "Fe Young's modulus (FE.E_Pa)",
    FE.nu: "Fe Poisson's ratio (FE.nu)",
    FE.sigma_s_Am2_kg: "Fe specific moment (FE.sigma_s_Am2_kg)",
    FE.K1_J_m3: "Fe anisotropy constant (FE.K1_J_m3)",
    FE.A_J_m: "Fe exchange constant (FE.A_J_m)",
    FE.density_kg_m3 * FE.sigma_s_Am2_kg: "Fe saturation magnetization (FE.Ms_A_m)",
    FE3O4.density_kg_m3: "Fe3O4 density (FE3O4.density_kg_m3)",
    FE3O4.sigma_s_Am2_kg: "Fe3O4 specific moment (FE3O4.sigma_s_Am2_kg)",
    FE3O4.K1_J_m3: "Fe3O4 anisotropy constant (FE3O4.K1_J_m3)",
    FE3O4.A_J_m: "Fe3O4 exchange constant (FE3O4.A_J_m)",
    PDMS.density_kg_m3: "PDMS density (PDMS.density_kg_m3)",
    PDMS.E_Pa: "PDMS Young's modulus (PDMS.E_Pa)",
    PDMS.nu: "PDMS Poisson's ratio (PDMS.nu)",
    SEED.sigma_s_Am2_kg: "seed powder's specific moment (SEED.sigma_s_Am2_kg)",
    SEED.Ms_A_m: "seed particles' saturation magnetization (SEED.Ms_A_m)",
    GRAVITY_M_S2: "gravity (GRAVITY_M_S2)",
    1.380649e-23: "Boltzmann constant (scipy.constants.k)",
    1.25663706212e-06: "mu0 (scipy.constants.mu_0)",
    1.25663706127e-06: "mu0 (scipy.constants.mu_0)",
    4e-7: "mu0 / pi (scipy.constants.mu_0)",
}
#: mu0 retyped as an expression
MU0_TEXT = re.compile(r"4(\.0)?\s*\*\s*(np\.|math\.)?pi\s*\*\s*1(\.0)?e-0?7|"
                      r"(np\.|math\.)?pi\s*\*\s*4(\.0)?e-0?7")

#: (file, value): how many such literals are legitimate there, and why
ALLOWED = {
    ("homogenize/cli/cmd_cell.py", 0.45): (1, "the largest volume fraction --phi accepts, not PDMS"),
    ("homogenize/experiments/report.py", 0.45): (1, "figure height per row [in]"),
    ("homogenize/macro/pullin.py", 0.45): (1, "a trial factor of the lying strip's contact "
                                              "length (deep_contact_start), not PDMS"),
    ("homogenize/studies/paper.py", 0.45): (3, "Poisson's ratios swept by the locking and "
                                               "element studies (0.3, 0.45, 0.49), not PDMS"),
}


def stray_literals(source: str) -> list[tuple[int, float, str]]:
    """(line, value, what) of every numeric code literal in ``source`` that retypes a material
    number or physical constant, plus mu0 written as an expression."""
    out = []
    for node in ast.walk(ast.parse(source)):
        if (isinstance(node, ast.Constant) and type(node.value) in (int, float)
                and float(node.value) in STRAY):
            out.append((node.lineno, float(node.value), STRAY[float(node.value)]))
    for i, line in enumerate(source.splitlines(), 1):
        code = line.split("#", 1)[0]
        if MU0_TEXT.search(code) and not code.lstrip().startswith(('"', "'")):
            out.append((i, 4e-7, "mu0 as an expression (scipy.constants.mu_0)"))
    return out


def test_the_scan_finds_retyped_numbers():
    src = ("x = 7870.0 * 178.0\nrho = 1210\nE = 2e6\nMU0 = 4 * np.pi * 1e-7\n"
           "'''docstring: 7870 kg/m^3'''\n# comment 211e9\nk = 1.380649e-23 * T\n")
    assert sorted(v for _, v, _ in stray_literals(src)) == sorted(
        [7870.0, 178.0, 1210.0, 2e6, 1.380649e-23, 4e-7])
    assert stray_literals("from micro.materials import FE\nrho = FE.density_kg_m3\n") == []


def test_material_numbers_live_in_micro_materials_only():
    found = {}
    for pkg in ("micro", "homogenize"):
        for path in sorted((ROOT / pkg).rglob("*.py")):
            rel = path.relative_to(ROOT).as_posix()
            if rel == OWNER:
                continue
            for line, value, what in stray_literals(path.read_text(encoding="utf-8")):
                found.setdefault((rel, value), []).append(f"{rel}:{line}: {value!r} {what}")
    bad = []
    for key, hits in found.items():
        allowed = ALLOWED.get(key, (0, ""))[0]
        if len(hits) > allowed:
            bad += hits
    assert not bad, ("material numbers retyped outside micro/materials.py (refer to "
                     "micro.materials or scipy.constants instead):\n" + "\n".join(bad))
    unused = [k for k in ALLOWED if len(found.get(k, ())) < ALLOWED[k][0]]
    assert not unused, f"allow-list entries no longer needed: {unused}"
