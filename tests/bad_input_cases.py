"""The bad-input contract of ``mapsim``: one table of cases over every command and study key.

Each case is an argv (run in-process through :func:`homogenize.cli.main` in a fresh copy of the
fixture directory, or in a subprocess where Dask workers are involved), the expected exit code,
words the message must contain, and the files it may create. A case is judged:

* ``clean``     -- the expected exit code; a refusal is ONE line ``mapsim CMD: error: ...``
                   containing the words; nothing else written;
* ``traceback`` -- an exception escaped, or a traceback was printed;
* ``silent``    -- exit 0 where a refusal was expected (silently wrong);
* ``wrong``     -- another exit code or message than expected;
* ``left``      -- files created (or left behind) that the case does not allow;
* ``lost``      -- an input file changed or disappeared.

``tests/test_bad_input.py`` runs every case; ``python tests/bad_input_cases.py`` runs them all
and writes ``results/reliability.md`` with the counts per command.
"""
from __future__ import annotations

import contextlib
import hashlib
import io
import os
import shutil
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import h5py

ROOT = Path(__file__).resolve().parent.parent

STUDY = """\
[study]
name = "fixture"
seed = 7
realizations = 3
n_particles = 20
evaluator = "synthetic"

[grid]
phi = [0.01, 0.02]
B_T = 0.1
gradB_T_per_m = 1.78
"""

RVE_STUDY = """\
[study]
name = "rvefix"
seed = 3
realizations = 2
n_particles = 10
evaluator = "rve"

[grid]
phi = 0.02
B_T = 0.1
gradB_T_per_m = 1.78
"""


def _study(edit: str = "", base: str = RVE_STUDY) -> str:
    return base + edit


# Study files with one bad key each (the rve evaluator checks the most keys).
STUDIES = {
    "s_arrangement.toml": _study('arrangement = "foo"\n'),
    "s_law.toml": _study('law = "magic"\n'),
    "s_phi.toml": RVE_STUDY.replace("phi = 0.02", "phi = 0.9"),
    "s_phi_str.toml": RVE_STUDY.replace("phi = 0.02", 'phi = "a"'),
    "s_B.toml": RVE_STUDY.replace("B_T = 0.1", "B_T = -1"),
    "s_B_huge.toml": RVE_STUDY.replace("B_T = 0.1", "B_T = 1e6"),
    "s_gradB0.toml": RVE_STUDY.replace("gradB_T_per_m = 1.78", "gradB_T_per_m = 0"),
    "s_real1.toml": RVE_STUDY.replace("realizations = 2", "realizations = 1"),
    "s_real_float.toml": RVE_STUDY.replace("realizations = 2", "realizations = 1e9"),
    "s_real_huge.toml": RVE_STUDY.replace("realizations = 2", "realizations = 1000000000"),
    "s_seed.toml": RVE_STUDY.replace("seed = 3", "seed = -1"),
    "s_npart0.toml": RVE_STUDY.replace("n_particles = 10", "n_particles = 0"),
    "s_npart_huge.toml": RVE_STUDY.replace("n_particles = 10", "n_particles = 40000000"),
    "s_voxels.toml": RVE_STUDY.replace("n_particles = 10", "n_particles = 10\nfem = true\n"
                                       "voxels = 1000"),
    "s_voxels_mem.toml": RVE_STUDY.replace("n_particles = 10", "n_particles = 10\nfem = true\n"
                                           "voxels = 250"),
    "s_coarse.toml": RVE_STUDY.replace("n_particles = 10", "n_particles = 10\nfem = true\n"
                                       "voxels = 16\ncoarse_voxels = 16"),
    "s_coarse_nofem.toml": RVE_STUDY.replace("n_particles = 10", "n_particles = 10\n"
                                             "coarse_voxels = 8"),
    "s_conf.toml": RVE_STUDY.replace("n_particles = 10", "n_particles = 10\nconfidence = 1.5"),
    "s_evaluator.toml": RVE_STUDY.replace('evaluator = "rve"', 'evaluator = "magic"'),
    "s_unknown_key.toml": RVE_STUDY.replace("n_particles = 10", "n_particles = 10\ncolour = 1"),
    "s_unknown_table.toml": _study("[extras]\na = 1\n"),
    "s_not_toml.toml": "[study\nseed = 1\n",
    "s_no_grid.toml": RVE_STUDY.split("[grid]")[0],
    "s_empty_axis.toml": RVE_STUDY.replace("phi = 0.02", "phi = []"),
    "s_repeat_axis.toml": RVE_STUDY.replace("phi = 0.02", "phi = [0.02, 0.02]"),
    "s_mag_tol_str.toml": _study('[magnetics]\ntol = "abc"\n'),
    "s_mag_tol_big.toml": _study("[magnetics]\ntol = 0.5\n"),
    "s_mag_method.toml": _study('[magnetics]\nmethod = "magic"\n'),
    "s_mag_unknown.toml": _study("[magnetics]\nspeed = 1\n"),
    "s_rve_arr.toml": _study('[rve]\narrangement = "foo"\n'),
    "s_rve_gap.toml": _study("[rve]\ngap_m = -1e-9\n"),
    "s_rve_cluster.toml": _study("[rve]\ncluster_size = 1.5\n"),
    "s_rve_dir.toml": _study("[rve]\nchain_direction = [0, 0, 0]\n"),
    "s_rve_radius.toml": _study("[rve]\nmean_radius_m = 1e100\n"),
    "s_rve_unknown.toml": _study("[rve]\ncolour = 1\n"),
    "s_law_chi.toml": _study('law = "linear"\n[law]\nchi = -1\n'),
    "s_cell_nu.toml": RVE_STUDY.replace("n_particles = 10", "n_particles = 10\nfem = true")
    + "[cell]\nmatrix_nu = 0.7\n",
    "s_cell_E.toml": RVE_STUDY.replace("n_particles = 10", "n_particles = 10\nfem = true")
    + "[cell]\nparticle_E_Pa = 1e300\n",
    "s_cell_nofem.toml": _study("[cell]\nmatrix_nu = 0.3\n"),
    "s_synth_work.toml": STUDY + "[synthetic]\nwork_seconds = -1\n",
    "s_rs_two.toml": STUDY + "[rve_size]\nn_particles = [10, 20]\nrealizations = 4\n",
    "s_rs_comp.toml": STUDY + "[rve_size]\nn_particles = [10, 20, 40]\ncomponent = \"w\"\n",
    "s_rs_prec.toml": STUDY + "[rve_size]\nn_particles = [10, 20, 40]\ntarget_rel_precision = 2\n",
}

TENSILE_CSV = "specimen,phi,strain,stress_Pa\n" + "".join(
    f"A,0.0,{e:.3f},{2e6 * e:.1f}\n" for e in (0.01, 0.02, 0.05, 0.1, 0.2))


def _exp(name: str, csv: str | None, data: str | None = None, kind: str = "tensile") -> dict:
    files = {f"{name}.toml": f'kind = "{kind}"\ndata = "{data or name + ".csv"}"\n'}
    if csv is not None:
        files[f"{name}.csv"] = csv
    return files


EXPERIMENTS = {}
for _files in (
        _exp("exp", TENSILE_CSV),
        _exp("e_mpa", "specimen,phi,strain,stress_Pa\n" + "".join(      # MPa in a Pa column
            f"A,0.0,{e:g},{2 * e:g}\n" for e in (0.01, 0.05, 0.1, 0.2))),
        _exp("e_percent", "specimen,phi,strain,stress_Pa\n" + "".join(
            f"A,0.0,{100 * e:g},{2e6 * e:.1f}\n" for e in (0.01, 0.05, 0.1, 0.2))),
        _exp("e_negative", "specimen,phi,strain,stress_Pa\n" + "".join(
            f"A,0.0,{e:g},{-2e6 * e:.1f}\n" for e in (0.01, 0.05, 0.1, 0.2))),
        _exp("e_dup", TENSILE_CSV + "A,0.0,0.050,100000.0\n"),
        _exp("e_devzero", None, data="/dev/zero"),
        _exp("e_dir", None, data="adir"),
        _exp("e_missing", None, data="nope.csv"),
        _exp("e_nan", "specimen,phi,strain,stress_Pa\nA,0.0,0.1,nan\n"),
        _exp("e_cols", "specimen,phi,strain\nA,0.0,0.1\n"),
        _exp("e_mm", "specimen,phi,length_m,width_m,thickness_m,B_T,gradB_T_per_m,deflection_m\n"
             "A,0.02,0.02,0.005,0.001,0.1,1.78,4.0\n", kind="deflection"),
        _exp("e_emu", "specimen,phi,H_A_per_m,M_A_per_m\nA,0.01,1e5,1e7\n",
             kind="magnetization"),
        _exp("e_mT", "specimen,phi,aspect_ratio,B_T,strain\nA,0.2,1.0,100,1e-4\n",
             kind="magnetostriction")):
    EXPERIMENTS.update(_files)
EXPERIMENTS["e_kind.toml"] = 'kind = "bending"\ndata = "exp.csv"\n'
EXPERIMENTS["e_bad_toml.toml"] = 'kind = "tensile\n'
EXPERIMENTS["e_matrix.toml"] = 'kind = "tensile"\ndata = "exp.csv"\n[matrix]\nnu = 0.7\n'


def build_fixtures(d: Path) -> Path:
    """Write every input the cases read into ``d`` (once per session): an RVE and broken
    copies of it, the studies, a finished table with its parts, experiments, a directory."""
    from micro.particles import generate_rve
    from homogenize.tables._evaluate import get_evaluator
    from homogenize.tables._study import parse_study
    from homogenize.tables.batch import _part_path, _write_part, parts_dir_for, run_batch

    d.mkdir(parents=True, exist_ok=True)
    rve = generate_rve(0.05, 30, 1)
    rve.save(d / "rve.h5")
    for name, edit in (("overlap", "overlap"), ("nmismatch", "n"), ("version", "version"),
                       ("params", "params"), ("noattr", "noattr")):
        shutil.copy(d / "rve.h5", d / f"{name}.h5")
        with h5py.File(d / f"{name}.h5", "r+") as f:
            if edit == "overlap":
                c = f["centers_m"][()]
                c[1] = c[0] + 0.5 * f["radii_m"][0]
                f["centers_m"][...] = c
            elif edit == "n":
                f.attrs["n"] = 31
            elif edit == "version":
                f.attrs["format_version"] = 99
            elif edit == "params":
                f.attrs["params_json"] = "{not json"
            else:
                del f.attrs["box_m"]
    (d / "study.toml").write_text(STUDY)
    for name, text in STUDIES.items():
        (d / name).write_text(text)
    for name, text in EXPERIMENTS.items():
        (d / name).write_text(text)
    (d / "adir").mkdir()
    (d / "disc.md").write_text("notes\n")
    # a finished table: parts computed here, in-process, so that run_batch needs no Dask
    study = parse_study(STUDY, str(d / "study.toml"))
    ev = get_evaluator("synthetic")
    parts = parts_dir_for(d / "table.h5")
    for t in study.tasks():
        k = t.key(ev.id)
        _write_part(_part_path(parts, t, k), t, k, ev(t))
    run_batch(study, d / "table.h5", progress=False)
    for hook in FIXTURE_HOOKS:              # more fixtures, defined with their cases below
        hook(d)
    return d


LONG = "x" * 300 + ".json"


@dataclass(frozen=True)
class Case:
    """One bad (or good) input. ``argv`` runs in a copy of the fixtures; ``creates``: file
    names the case may create (a successful run); ``subprocess``: run ``mapsim`` as a process
    (commands that start Dask workers)."""

    cmd: str
    argv: tuple
    code: int = 2
    words: tuple = ()
    creates: tuple = ()
    subprocess: bool = False
    note: str = ""

    @property
    def id(self) -> str:
        return " ".join(self.argv)[:90]


def C(*argv, code=2, words=(), creates=(), subprocess=False, note=""):
    return Case(argv[0], tuple(argv), code, tuple(words), tuple(creates), subprocess, note)


# a quick cylinder for `mapsim specimen` (each bad case changes one option)
_SPEC = ("specimen", "--shape", "cylinder", "--radius-m", "1e-3", "--length-m", "1.6e-3",
         "--law", "froehlich-kennelly", "--chi0", "2", "--Ms-A-per-m", "1e5",
         "--shear-modulus-Pa", "1e5")

_EXPORT = ("export", "--to", "abaqus", "--body-force-N-m3", "4e4", "--E-Pa", "2e6", "--nu",
           "0.45", "--density-kg-m3", "1210")

CASES = [
    # ------------------------------------------------------------------ rve
    C("rve", "--n", "50000000", words=("--n 50000000", "GiB", "memory")),
    C("rve", "--n", "0", words=("--n", "[1,")),
    C("rve", "--n", "ten", words=("--n", "integer")),
    C("rve", "--phi", "0", words=("--phi", "(0, 0.6]")),
    C("rve", "--phi", "0.9", words=("--phi", "0.6")),
    C("rve", "--phi", "nan", words=("--phi",)),
    C("rve", "--distribution", "monodisperse", "--radius", "1e100", words=("--radius", "1e100")),
    C("rve", "--mean-radius=-1e-9", words=("--mean-radius",)),
    C("rve", "--gsd", "1", words=("--gsd", "(1,")),
    C("rve", "--r-min", "6e-8", words=("r_min", "r_max")),
    C("rve", "--calibrate-sigma", "1e9", words=("--calibrate-sigma", "A m^2/kg")),
    C("rve", "--calibrate-sigma=-5", words=("--calibrate-sigma",)),
    C("rve", "--core-density", "0", words=("--core-density", "kg/m^3")),
    C("rve", "--shell", "1", words=("--shell", "m")),
    C("rve", "--gap=-1e-9", words=("--gap",)),
    C("rve", "--cluster-size", "1", words=("--cluster-size",)),
    C("rve", "--cluster-density", "0.9", words=("--cluster-density",)),
    C("rve", "--chain-spread", "500", words=("--chain-spread", "deg")),
    C("rve", "--agglomerated-fraction", "1.5", words=("--agglomerated-fraction",)),
    C("rve", "--seed=-1", words=("--seed",)),
    C("rve", "--B", "1e9", words=("--B", "T")),
    C("rve", "--B", "0.1", "--gradB", "inf", words=("--gradB",)),
    C("rve", "--B", "0.1", "--tol", "0.5", words=("--tol", "0.01")),
    C("rve", "--B", "0.1", "--tol", "abc", words=("--tol",)),
    C("rve", "--B", "0.1", "--accuracy", "0", words=("--accuracy",)),
    C("rve", "--B", "0.1", "--demag-factor", "2", words=("--demag-factor", "[0, 1]")),
    C("rve", "--B", "0.1", "--T", "0", words=("--T", "K")),
    C("rve", "--law", "magic", words=("--law",)),
    C("rve", "--load", "rve.h5", "--out", "rve.h5", words=("--out", "input")),
    C("rve", "--n", "20", "--json", "fifo", words=("--json", "not a regular file")),
    C("rve", "--n", "20", "--json", "adir", words=("--json", "directory")),
    C("rve", "--n", "20", "--out", "x.txt", words=("--out", ".h5")),
    C("rve", "--n", "20", "--json", LONG, words=("--json", "too long")),
    C("rve", "--load", "overlap.h5", words=("overlap.h5", "overlap")),
    C("rve", "--load", "nmismatch.h5", words=("nmismatch.h5", "n = 31", "30")),
    C("rve", "--load", "version.h5", words=("version.h5", "format_version")),
    C("rve", "--load", "params.h5", words=("params.h5", "params_json")),
    C("rve", "--load", "noattr.h5", words=("noattr.h5", "box_m")),
    C("rve", "--load", "nope.h5", words=("nope.h5", "does not exist")),
    C("rve", "--load", "study.toml", words=("study.toml", "HDF5")),
    C("rve", "--histogram", "adir", words=("--histogram", "regular file")),
    C("rve", "--histogram", "nope.csv", words=("nope.csv", "does not exist")),
    C("rve", "--n", "20", "--phi", "0.05", "--json", "s.json", code=0, creates=("s.json",)),
    C("rve", "--load", "rve.h5", "--out", "copy.h5", code=0,
      creates=("copy.h5", "copy.manifest.json")),
    # ------------------------------------------------------------------ homogenize
    C("homogenize", "rve.h5", "--json", "rve.h5", words=("--json", "input")),
    C("homogenize", "rve.h5", "--voxels", "200", "--json", "h.json",
      words=("--voxels 200", "GiB", "memory")),
    C("homogenize", "rve.h5", "--voxels", "2", "--json", "h.json", words=("--voxels", "[4,")),
    C("homogenize", "rve.h5", "--particle-E", "1e300", "--json", "h.json",
      words=("--particle-E", "Pa")),
    C("homogenize", "rve.h5", "--matrix-E", "0", "--json", "h.json", words=("--matrix-E",)),
    C("homogenize", "rve.h5", "--matrix-nu", "0.5", "--json", "h.json", words=("--matrix-nu",)),
    C("homogenize", "rve.h5", "--tol", "0.1", "--json", "h.json", words=("--tol", "0.01")),
    C("homogenize", "rve.h5", "--B", "nan", "--json", "h.json", words=("--B", "T")),
    C("homogenize", "rve.h5", "--B", "1,2", "--json", "h.json", words=("--B", "--B-direction")),
    C("homogenize", "rve.h5", "--B", "0.1", "--B-direction", "0", "0", "0", "--json", "h.json",
      words=("--B-direction", "zero")),
    C("homogenize", "rve.h5", "--gradB", "1", "--json", "h.json", words=("--gradB", "--B")),
    C("homogenize", "nope.h5", "--json", "h.json", words=("nope.h5", "does not exist")),
    C("homogenize", "overlap.h5", "--json", "h.json", words=("overlap",)),
    C("homogenize", "params.h5", "--json", "h.json", words=("params_json",)),
    C("homogenize", "rve.h5", "--json", "fifo", words=("--json", "not a regular file")),
    C("homogenize", "rve.h5", "--json", "h.json", "--vtu", "adir", words=("--vtu", "directory")),
    # ------------------------------------------------------------------ cell studies
    C("cell-dilute-study", "--voxels", "8,abc", "--json", "d.json", words=("--voxels",)),
    C("cell-dilute-study", "--voxels", "2", "--json", "d.json", words=("--voxels", "[4, 256]")),
    C("cell-dilute-study", "--voxels", "250", "--json", "d.json", words=("--voxels", "GiB")),
    C("cell-dilute-study", "--voxels", "8,200", "--method", "cut", "--json", "d.json",
      words=("--voxels 200", "--method cut", "GiB")),
    C("cell-dilute-study", "--phi", "0.5", "--json", "d.json", words=("--phi",)),
    C("cell-dilute-study", "--particle-E", "0", "--json", "d.json", words=("--particle-E",)),
    C("cell-dilute-study", "--json", "adir", words=("--json", "directory")),
    C("cell-phi-study", "--phi", "0.9", "--json", "p.json", words=("--phi", "0.45")),
    C("cell-phi-study", "--phi", "a,b", "--json", "p.json", words=("--phi",)),
    C("cell-phi-study", "--voxels", "1000", "--json", "p.json", words=("--voxels",)),
    C("cell-phi-study", "--voxels", "200", "--json", "p.json", words=("--voxels", "GiB")),
    # ------------------------------------------------------------------ batch and studies
    C("batch", "study.toml", "--out", "study.toml", words=("--out", "input")),
    C("batch", "study.toml", "--out", "rve.h5", words=("rve.h5", "not a mapsim table")),
    C("batch", "s_seed.toml", "--out", "table.h5", words=("seed",)),
    C("batch", "study.toml", "--out", "fifo", words=("--out", "not a regular file")),
    C("batch", "study.toml", "--out", "t.h5", "--scheduler", "not a url",
      words=("--scheduler", "tcp://")),
    C("batch", "study.toml", "--out", "t.h5", "--workers", "0", words=("--workers",)),
    C("batch", "study.toml", "--out", "t.h5", "--retries=-1", words=("--retries",)),
    C("batch", "adir", "--out", "t.h5", words=("adir", "regular file")),
    C("batch", "nope.toml", "--out", "t.h5", words=("nope.toml", "does not exist")),
    C("batch", "study.toml", "--out", LONG, words=("--out", "too long")),
    C("batch", "study.toml", "--out", "table.h5", "--no-progress", code=0,
      note="resume: every part stored, nothing recomputed"),
    *[C("batch", name, "--out", "t.h5", words=(name, *w)) for name, w in (
        ("s_arrangement.toml", ("arrangement", "foo")),
        ("s_law.toml", ("law", "magic")),
        ("s_phi.toml", ("phi", "0.6")),
        ("s_phi_str.toml", ("phi", "numbers")),
        ("s_B.toml", ("B_T", ">= 0")),
        ("s_B_huge.toml", ("B_T", "50")),
        ("s_gradB0.toml", ("gradB_T_per_m",)),
        ("s_real1.toml", ("realizations", ">= 2")),
        ("s_real_float.toml", ("realizations", "integer")),
        ("s_real_huge.toml", ("realizations", "GiB")),
        ("s_seed.toml", ("seed", ">= 0")),
        ("s_npart0.toml", ("n_particles",)),
        ("s_npart_huge.toml", ("n_particles", "GiB")),
        ("s_voxels.toml", ("voxels", "256")),
        ("s_voxels_mem.toml", ("voxels", "GiB")),
        ("s_coarse.toml", ("coarse_voxels", "[4, voxels - 1] = [4, 15]", "16")),
        ("s_coarse_nofem.toml", ("coarse_voxels", "fem = false")),
        ("s_conf.toml", ("confidence", "(0, 1)")),
        ("s_evaluator.toml", ("evaluator",)),
        ("s_unknown_key.toml", ("colour",)),
        ("s_unknown_table.toml", ("extras",)),
        ("s_not_toml.toml", ("TOML",)),
        ("s_no_grid.toml", ("[grid]",)),
        ("s_empty_axis.toml", ("phi", "empty")),
        ("s_repeat_axis.toml", ("phi", "repeated")),
        ("s_mag_tol_str.toml", ("[magnetics] tol", "abc")),
        ("s_mag_tol_big.toml", ("[magnetics] tol", "0.01")),
        ("s_mag_method.toml", ("[magnetics] method", "magic")),
        ("s_mag_unknown.toml", ("[magnetics]", "speed")),
        ("s_rve_arr.toml", ("[rve] arrangement", "foo")),
        ("s_rve_gap.toml", ("[rve] gap_m",)),
        ("s_rve_cluster.toml", ("[rve] cluster_size", "integer")),
        ("s_rve_dir.toml", ("[rve] chain_direction",)),
        ("s_rve_radius.toml", ("[rve] mean_radius_m",)),
        ("s_rve_unknown.toml", ("[rve]", "colour")),
        ("s_law_chi.toml", ("[law] chi",)),
        ("s_cell_nu.toml", ("[cell] matrix_nu",)),
        ("s_cell_E.toml", ("[cell] particle_E_Pa",)),
        ("s_cell_nofem.toml", ("[cell]", "fem")),
        ("s_synth_work.toml", ("work_seconds",)),
        ("s_rs_comp.toml", ("[rve_size] component",)),
        ("s_rs_prec.toml", ("[rve_size] target_rel_precision",)),
    )],
    C("batch", "s_run_jam.toml", "--out", "t.h5", "--no-progress", "--workers", "1",
      words=("realizations refused", "phi"), subprocess=True,
      note="a deterministic error in the workers: not retried, one line"),
    # ------------------------------------------------------------------ rve-size
    C("rve-size", "study.toml", "--out", "rs", words=("[rve_size]",)),
    C("rve-size", "s_rs_two.toml", "--out", "rs", words=("three",)),
    C("rve-size", "study.toml", "--out", "rs", "--target", "2", words=("--target",)),
    C("rve-size", "study.toml", "--out", "rs", "--workers", "0", words=("--workers",)),
    C("rve-size", "study.toml", "--out", "rs", "--scheduler", "x", words=("--scheduler",)),
    C("rve-size", "study.toml", "--out", "fifo", words=("--out", "not a directory")),
    # ------------------------------------------------------------------ compare
    C("compare", "--seed=-1", "table.h5", "0", "1", words=("--seed",)),
    C("compare", "table.h5", "0", "0", words=("same grid point",)),
    C("compare", "table.h5", "0", "99", words=("out of range",)),
    C("compare", "table.h5", "0", "phi=0.5", words=("phi=0.5", "matches no")),
    C("compare", "table.h5", "0", "1", "--permutations", "5", words=("--permutations",)),
    C("compare", "table.h5", "0", "1", "--confidence", "1.5", words=("--confidence",)),
    C("compare", "table.h5", "0", "1", "--quantity", "zzz", words=("zzz",)),
    C("compare", "table.h5", "0", "1", "--component", "q", words=("component",)),
    C("compare", "nope.h5", "0", "1", words=("nope.h5", "does not exist")),
    C("compare", "rve.h5", "0", "1", words=("rve.h5", "not a mapsim table")),
    C("compare", "table.h5", "0", "1", "--json", "table.h5", words=("--json", "input")),
    C("compare", "table.h5", "0", "1", "--json", "c.json", code=0, creates=("c.json",)),
    # ------------------------------------------------------------------ chain
    C("chain", "study.toml", "--thickness=-1", words=("--thickness",)),
    C("chain", "study.toml", "--width", "0", words=("--width",)),
    C("chain", "study.toml", "--workers", "0", words=("--workers",)),
    C("chain", "study.toml", "--out", "fifo", words=("--out", "not a directory")),
    C("chain", "s_arrangement.toml", "--out", "ch", words=("arrangement",)),
    # ------------------------------------------------------------------ beam
    C("beam", "--nz", "60", words=("--nz 60", "GiB", "memory")),
    C("beam", "--nz", "500", words=("--nz", "[1, 128]")),
    C("beam", "--body-force-N-m3", "1e30", words=("--body-force-N-m3", "N/m^3")),
    C("beam", "--E-Pa", "0", words=("--E-Pa", "Pa")),
    C("beam", "--nu", "0.5", words=("--nu",)),
    C("beam", "--length-m=-1", words=("--length-m",)),
    C("beam", "--thickness-m", "1e9", words=("--thickness-m",)),
    C("beam", "--steps", "0", words=("--steps",)),
    C("beam", "--order", "3", words=("--order",)),
    C("beam", "--json", "fifo", words=("--json", "not a regular file")),
    C("beam", "--table", "nope.h5", "--phi", "0.01", "--B", "0.1", "--gradB", "1.78",
      words=("nope.h5",)),
    C("beam", "--table", "table.h5", words=("--phi", "required")),
    C("beam", "--table", "table.h5", "--phi", "0.01", "--B", "5", "--gradB", "1.78",
      "--model", "eb", words=("B_T = 5 T", "only")),
    C("beam", "--table", "table.h5", "--phi", "2", "--B", "0.1", "--gradB", "1.78",
      words=("--phi",)),
    C("beam", "--magnet", "cuboid", words=("--magnet-position",)),
    C("beam", "--magnet", "cuboid", "--magnet-size", "0", "1", "1", words=("--magnet-size",)),
    C("beam", "--magnet", "coil", "--turns", "0", words=("--turns",)),
    C("beam", "--model", "eb", "--json", "b.json", code=0, creates=("b.json",)),
    # ------------------------------------------------------------------ channel
    C("channel", "--nc", "0", words=("--nc",)),
    C("channel", "--close", "--flow-rate-m3-s", "1e-10", "--json", "c.json",
      words=("--close", "flow rate never shuts")),
    C("channel", "--close", "--png", "c.png", "--pressure-drop-Pa", "10",
      words=("--close", "--png")),
    C("channel", "--table", "table.h5", "--phi", "0.02", "--gradB", "1.78",
      words=("--table", "--close")),
    C("channel", "--nc", "100", words=("--nc", "64")),
    C("channel", "--a-m", "0", words=("--a-m",)),
    C("channel", "--body-force-N-m3", "1e30", words=("--body-force-N-m3",)),
    C("channel", "--flow-rate-m3-s=-1", words=("--flow-rate-m3-s",)),
    C("channel", "--flow-rate-m3-s", "1e-9", "--pressure-drop-Pa", "100", words=("not both",)),
    C("channel", "--target-gap-m", "1e-5", words=("--target-gap-m", "needs")),
    C("channel", "--viscosity-Pa-s", "0", words=("--viscosity-Pa-s",)),
    C("channel", "--json", "adir", words=("--json", "directory")),
    # ------------------------------------------------------------------ export
    C(*_EXPORT, "--table", "table.h5", "--out", "table.h5", words=("--out", "input")),
    C("export", "--to", "foo", "--out", "-", words=("--to",)),
    C(*_EXPORT[:5], "--E-Pa=-1", "--nu", "0.45", "--density-kg-m3", "1210", "--out", "-",
      words=("--E-Pa",)),
    C(*_EXPORT[:7], "--nu", "0.7", "--density-kg-m3", "1210", "--out", "-", words=("--nu",)),
    C("export", "--to", "abaqus", "--body-force-N-m3=-5", "--E-Pa", "2e6", "--nu", "0.45",
      "--density-kg-m3", "1210", "--out", "-", words=("--body-force-N-m3",)),
    C("export", "--to", "abaqus", "--body-force-N-m3", "4e4", "--matrix-material", "jelly",
      "--out", "x.inp", words=("--matrix-material", "jelly", "sylgard184-10to1")),
    C(*_EXPORT, "--out", "fifo", words=("--out", "not a regular file")),
    C(*_EXPORT, "--out", "adir", words=("--out", "directory")),
    C(*_EXPORT, "--deck", "cantilever", "--out", "-", words=("--deck",)),
    C(*_EXPORT, "--deck", "cantilever", "--deck-nz", "99", "--out", "d.inp",
      words=("--deck-nz",)),
    C(*_EXPORT, "--out", "x.inp", code=0, creates=("x.inp",)),
    # ------------------------------------------------------------------ paper
    C("paper", "--width-m", "0", words=("--width-m",)),
    C("paper", "--out", "fifo", words=("--out", "not a directory")),
    C("paper", "--json", "adir", words=("--json", "directory")),
    # ------------------------------------------------------------------ diagnose
    C("diagnose", "exp.toml", "--json", "exp.csv", words=("--json", "input")),
    C("diagnose", "exp.toml", "--json", "exp.toml", words=("--json", "input")),
    C("diagnose", "e_devzero.toml", words=("/dev/zero", "regular file")),
    C("diagnose", "e_dir.toml", words=("adir", "regular file")),
    C("diagnose", "e_missing.toml", words=("nope.csv", "not found")),
    C("diagnose", "e_mpa.toml", words=("stress_Pa", "MPa", "row 2")),
    C("diagnose", "e_percent.toml", words=("strain", "percent")),
    C("diagnose", "e_negative.toml", words=("stress_Pa", "compressive")),
    C("diagnose", "e_dup.toml", words=("row 7", "repeats row 4")),
    C("diagnose", "e_nan.toml", words=("stress_Pa", "finite")),
    C("diagnose", "e_cols.toml", words=("stress_Pa", "missing")),
    C("diagnose", "e_mm.toml", words=("deflection_m", "mm")),
    C("diagnose", "e_emu.toml", words=("M_A_per_m", "saturation")),
    C("diagnose", "e_mT.toml", words=("B_T", "mT")),
    C("diagnose", "e_kind.toml", words=("kind",)),
    C("diagnose", "e_bad_toml.toml", words=("TOML",)),
    C("diagnose", "e_matrix.toml", words=("[matrix] nu",)),
    C("diagnose", "nope.toml", words=("nope.toml", "not found")),
    C("diagnose", "adir", words=("adir", "regular file")),
    C("diagnose", "exp.toml", "--json", "fifo", words=("--json", "not a regular file")),
    C("diagnose", "exp.toml", "--report", "fifo", words=("--report", "not a directory")),
    C("diagnose", "exp.toml", "--discussion", "adir", words=("--discussion", "--report")),
    C("diagnose", "exp.toml", "--report", "rep", "--discussion", "adir",
      words=("--discussion", "regular file")),
    # ------------------------------------------------------------------ diagnose-study/tables
    C("diagnose-study", "--n", "0", words=("--n",)),
    C("diagnose-study", "--n", "1000000", words=("--n",)),
    C("diagnose-study", "--seed=-1", words=("--seed",)),
    C("diagnose-study", "--out", "fifo", words=("--out", "not a directory")),
    C("diagnose-study", "--json", "adir", words=("--json", "directory")),
    C("diagnose-tables", "--voxels", "4", words=("--voxels",)),
    C("diagnose-tables", "--voxels", "1000", words=("--voxels",)),
    C("diagnose-tables", "--only", "foo", words=("--only",)),
    # ------------------------------------------------------------------ bench
    C("bench", "--only", "foo", words=("--only",)),
    C("bench", "--json", "fifo", words=("--json", "not a regular file")),
    C("bench", "--json", "adir", words=("--json", "directory")),
    # ------------------------------------------------------------------ relax
    C("relax", "rve.h5", "--B", "1,0.5", "--json", "o.json", words=("strictly increasing",)),
    C("relax", "rve.h5", "--B", "0:1:x", "--json", "o.json", words=("--B", "START:STOP:COUNT")),
    C("relax", "rve.h5", "--matrix-E", "0", "--json", "o.json", words=("--matrix-E",)),
    C("relax", "rve.h5", "--near-field", "maybe", "--json", "o.json", words=("--near-field",)),
    C("relax", "rve.h5", "--mean-strain", "0,0,0,0,0,0", "--json", "o.json",
      words=("--mean-strain", "--boundary strain")),
    C("relax", "rve.h5", "--boundary", "strain", "--mean-strain", "1e-3,0", "--json", "o.json",
      words=("--mean-strain", "six")),
    C("relax", "rve.h5", "--boundary", "strain", "--mean-strain", "0.5,0,0,0,0,0", "--json",
      "o.json", words=("mean_strain", "0.1")),
    C("relax", "rve.h5", "--json", "rve.h5", words=("--json", "input")),
    # ------------------------------------------------------------------ specimen
    C(*_SPEC, "--B", "0.5,0.2", words=("--B", "increase strictly")),
    C(*_SPEC, "--B", "-0.1", words=("--B", ">= 0")),
    C(*_SPEC, "--B", "0:1:x", words=("--B", "START:STOP:COUNT")),
    C(*_SPEC, "--B", "0:100:3", words=("--B", "50 T")),
    C(*_SPEC, "--model", "magic", words=("--model",)),
    C(*_SPEC, "--model", "affine", words=("--model affine", "--phi")),
    C(*_SPEC, "--model", "relaxed", words=("--kappa", "relax tables")),
    C(*_SPEC, "--kappa", "0.2", words=("--kappa", "relaxed")),
    C(*_SPEC, "--phi", "0.1", words=("--phi", "affine")),
    C(*_SPEC, "--radius-m", "0", words=("--radius-m", "(0, 10]")),
    C(*_SPEC, "--radius-m=-1e-3", words=("--radius-m",)),
    C(*_SPEC, "--length-m", "0", words=("--length-m",)),
    C(*_SPEC, "--edge-radius-m", "6e-4", words=("--edge-radius-m", "[0, 0.0005)")),
    C(*_SPEC, "--edge-radius-m=-1e-4", words=("--edge-radius-m",)),
    C("specimen", "--shape", "sphere", "--radius-m", "1e-3", "--edge-radius-m", "1e-4", "--law",
      "linear", "--chi", "1", "--shear-modulus-Pa", "1e5", words=("--edge-radius-m", "sphere")),
    C(*_SPEC, "--nu", "0.5", words=("--nu", "(-1, 0.5)")),
    C(*_SPEC, "--nu=-1", words=("--nu", "(-1, 0.5)")),
    C(*_SPEC, "--matrix-E-Pa", "1e6", words=("--shear-modulus-Pa", "--matrix-E-Pa")),
    C(*_SPEC, "--n-mesh", "1", words=("--n-mesh", "[2, 64]")),
    C(*_SPEC, "--n-boundary", "8", words=("--n-boundary", "[16, 1024]")),
    C(*_SPEC, "--json", "adir", words=("--json", "directory")),
    C(*_SPEC, "--png", "fifo", words=("--png", "not a regular file")),
    C(*_SPEC, "--json", "s.json", "--vtu", "s.json", words=("--vtu", "also given")),
    C("specimen", "--shape", "cube", "--radius-m", "1e-3", "--law", "linear", "--chi", "1",
      "--shear-modulus-Pa", "1e5", words=("--shape",)),
    C("specimen", "--shape", "sphere", "--radius-m", "1e-3", "--law", "magic", "--chi", "1",
      "--shear-modulus-Pa", "1e5", words=("--law",)),
    C("specimen", "--shape", "sphere", "--radius-m", "1e-3", "--law", "langevin", "--chi0",
      "2", "--shear-modulus-Pa", "1e5", words=("--law langevin", "--Ms-A-per-m")),
    C("specimen", "--shape", "sphere", "--radius-m", "1e-3", "--law", "linear", "--chi0", "2",
      "--shear-modulus-Pa", "1e5", words=("--law linear", "--chi")),
    C("specimen", "--shape", "sphere", "--radius-m", "1e-3", "--length-m", "2e-3", "--law",
      "linear", "--chi", "1", "--shear-modulus-Pa", "1e5", words=("--length-m", "sphere")),
    C("specimen", "--shape", "cylinder", "--radius-m", "1e-3", "--law", "linear", "--chi",
      "1", "--shear-modulus-Pa", "1e5", words=("--length-m", "cylinder")),
    C("specimen", "--shape", "sphere", "--radius-m", "1e-3", "--law", "linear", "--chi", "1",
      words=("--shear-modulus-Pa", "--matrix-E-Pa")),
    C(*_SPEC, "--B", "0.2", "--n-mesh", "4", "--n-boundary", "24", "--json", "s.json",
      "--quiet", code=0, creates=("s.json",)),
    # ------------------------------------------------------------------ issue 36
    # negative numbers in scientific notation reach the range check (argparse read them as
    # options: "expected one argument", "expected 3 arguments")
    C("rve", "--mean-radius", "-1e-6", words=("--mean-radius", "[1e-10, 0.001] m")),
    C("rve", "--chain-direction", "-1e-3", "0", "-1e9", "--arrangement", "chains",
      words=("--chain-direction", "-1e9")),
    C("beam", "--magnet", "cuboid", "--magnet-size", "1e-2", "1e-2", "1e-2", "--remanence-T",
      "1.3", "--magnet-position", "20e-3", "2.5e-3", "-15.5e3",
      words=("--magnet-position", "[-10, 10] m", "-15.5e3")),
    C("beam", "--body-force-N-m3", "-1E+10", words=("--body-force-N-m3", "-1E+10")),
    C("channel", "--outlet-pressure-Pa", "-1e9", words=("--outlet-pressure-Pa",)),
    C("rve", "--particle-material", "unobtainium", words=("--particle-material",
                                                          "carbonyl-iron")),
    C("rve", "--phi", "0.10", "--n", "20", "--mean-radius", "1e-6", "--json", "m.json", code=0,
      creates=("m.json",), note="a micron powder: the bounds follow the mean radius"),
    C("beam", "--model", "eb", "--magnet", "cuboid", "--magnet-size", "1e-2", "1e-2", "1e-2",
      "--remanence-T", "1.3", "--magnet-position", "20e-3", "2.5e-3", "-15.5e-3", code=0,
      note="a magnet below the strip: a negative coordinate in scientific notation"),
]

# Every key of every table of a study file, each with one bad value (the rve evaluator, which
# checks the most): (table, key, bad TOML value, words of the message).
STUDY_KEYS = [
    ("study", "name", "1", ("name", "string")),
    ("study", "fem", '"yes"', ("fem", "true or false")),
    ("study", "description", "[1]", ("description", "string")),
    ("study", "voxels", "2", ("voxels", "[4, 256]")),
    ("grid", "distribution", '"gamma"', ("distribution", "gamma")),
    ("grid", "mean_radius_m", "1e-2", ("mean_radius_m",)),
    ("grid", "gsd", "0.5", ("gsd",)),
    ("grid", "shell_thickness_m", "-1e-9", ("shell_thickness_m",)),
    ("grid", "gap_m", '"wide"', ("gap_m",)),
    ("grid", "colour", "1", ("colour",)),
    ("rve", "placement", '"magic"', ("placement", "magic")),
    ("rve", "cluster_density", "0.9", ("cluster_density",)),
    ("rve", "chain_length", "0.5", ("chain_length",)),
    ("rve", "chain_spread_deg", "400", ("chain_spread_deg", "deg")),
    ("rve", "agglomerated_fraction", "2", ("agglomerated_fraction",)),
    ("rve", "max_attempts", "0", ("max_attempts",)),
    ("rve", "r_min_m", "-1", ("r_min_m",)),
    ("rve", "r_max_m", "1", ("r_max_m",)),
    ("rve", "core_density_kg_m3", "0", ("core_density_kg_m3",)),
    ("rve", "shell_density_kg_m3", "1e9", ("shell_density_kg_m3",)),
    ("rve", "core_sigma_Am2_kg", "1e9", ("core_sigma_Am2_kg",)),
    ("rve", "shell_sigma_Am2_kg", "-1", ("shell_sigma_Am2_kg",)),
    ("rve", "calibrate_sigma_Am2_kg", "0", ("calibrate_sigma_Am2_kg",)),
    ("magnetics", "accuracy", "0", ("accuracy",)),
    ("magnetics", "summation", '"fast"', ("summation", "fast")),
    ("magnetics", "max_iter", "0", ("max_iter",)),
    ("magnetics", "damping", "2", ("damping",)),
    ("magnetics", "precondition", "1", ("precondition", "true or false")),
    ("magnetics", "demag_factor", "1.5", ("demag_factor",)),
    ("magnetics", "rho_kg_m3", "-1", ("rho_kg_m3",)),
    ("magnetics", "sigma_s_Am2_kg", "1e9", ("sigma_s_Am2_kg",)),
    ("magnetics", "c_powder", "0", ("c_powder",)),
    ("law", "T_K", "-5", ("T_K",)),
    ("law", "chi_i", "0", ("chi_i",)),
    ("law", "measurement_time_s", "0", ("measurement_time_s",)),
    ("cell", "tol", "0.5", ("tol", "0.01")),
    ("cell", "method", '"magic"', ("method", "magic")),
    ("cell", "rigid", '"no"', ("rigid", "true or false")),
    ("cell", "maxiter", "0", ("maxiter",)),
    ("cell", "particle_nu", "0.5", ("particle_nu",)),
    ("cell", "matrix_E_Pa", '"soft"', ("matrix_E_Pa",)),
    ("rve_size", "realizations", "2", ("realizations", ">= 3")),
    ("rve_size", "quantity", '"speed"', ("quantity", "speed")),
    ("rve_size", "n_particles", "[10, 20, 0]", ("n_particles",)),
    ("rve_size", "target", "1", ("target",)),
    ("study", "particle_material", '"unobtainium"', ("particle_material", "carbonyl-iron")),
    ("study", "matrix_material", '"jelly"', ("matrix_material", "sylgard184-10to1")),
]


def _key_study(table: str, key: str, value: str) -> str:
    head = RVE_STUDY
    if table == "cell":
        head = head.replace("n_particles = 10", "n_particles = 10\nfem = true")
    if table == "study":
        head = "\n".join(ln for ln in head.splitlines() if not ln.startswith(f"{key} ="))
        return head.replace("[study]", f"[study]\n{key} = {value}") + "\n"
    if table == "grid":
        return head.replace("[grid]", f"[grid]\n{key} = {value}")
    if table == "rve_size":
        rs = {"n_particles": "[10, 20, 40]", "realizations": "4", key: value}
        return head + "[rve_size]\n" + "".join(f"{k} = {v}\n" for k, v in rs.items())
    if table == "law":
        return head.replace("[grid]", '[grid]\nlaw = "regime"') + f"[law]\n{key} = {value}\n"
    return head + f"[{table}]\n{key} = {value}\n"


for _t, _k, _v, _w in STUDY_KEYS:
    _name = f"k_{_t}_{_k}.toml"
    STUDIES[_name] = _key_study(_t, _k, _v)
    CASES.append(C("batch", _name, "--out", "t.h5", words=(_name, f"[{_t}]", *_w)))

# the study of the subprocess case: random sequential addition cannot reach phi = 0.55, so
# every realization fails the same way in the workers
STUDIES["s_run_jam.toml"] = RVE_STUDY.replace("phi = 0.02", "phi = 0.55").replace(
    "n_particles = 10", "n_particles = 40") + '[rve]\nplacement = "rsa"\nmax_attempts = 200\n'


# --------------------------------------------------------------------------- issue 38
# The holes found by trying things as a new user would: an output that is an input of the same
# run (also inside an output directory), values read back (tables, RVE files) trusted, a FIFO
# opened, geometry that contradicts a model's slender-body assumption, ambiguous inputs, and
# a refusal that leaves a directory behind.
FIXTURE_HOOKS: list = []

_CHAIN_STUDY = STUDY.replace("B_T = 0.1", "B_T = [0.1, 0.2]")
STUDIES.update({
    "s_chain.toml": _CHAIN_STUDY,
    "s_chain_relax.toml": _CHAIN_STUDY.replace('evaluator = "synthetic"', 'evaluator = "relax"'),
    "s_chain_multi.toml": _CHAIN_STUDY.replace("[grid]", '[grid]\nlaw = ["linear", "regime"]'),
    "s_rs_ok.toml": STUDY + "[rve_size]\nn_particles = [10, 20, 40]\nrealizations = 3\n",
})
EXPERIMENTS.update(_exp("e_empty", "specimen,phi,strain,stress_Pa\n"))
EXPERIMENTS.update(_exp(
    "e_long", "specimen,phi,length_m,width_m,thickness_m,B_T,gradB_T_per_m,deflection_m\n"
    "A,0.02,0.02,0.005,0.001,0.1,1.78,0.001\nA,0.02,0.02,0.005,0.001,0.2,1.78,0.03\n",
    kind="deflection"))
EXPERIMENTS["e_fifo.toml"] = 'kind = "tensile"\ndata = "fifo"\n'
EXPERIMENTS.update(_exp("e_amb", "specimen,phi,strain,stress_Pa,stress_MPa\n"
                                 "A,0.0,0.01,20000,0.02\nA,0.0,0.05,100000,0.1\n"))
EXPERIMENTS["e_inrep.toml"] = 'kind = "tensile"\ndata = "myrep/data.png"\n'
EXPERIMENTS["h_both.csv"] = "radius_m,count,weight\n1e-6,3,0.5\n2e-6,4,0.5\n"
EXPERIMENTS["h_dup.csv"] = "radius_m,count,radius_m\n1e-6,3,1e-6\n2e-6,4,2e-6\n"
EXPERIMENTS["h_none.csv"] = "radius_m,amount\n1e-6,3\n2e-6,4\n"


def _issue38_fixtures(d: Path) -> None:
    """A report directory holding the user's notes and data, a chain directory holding the
    study, tables and RVE files edited after they were written, a table whose side-car is a
    directory and whose parts directory is a file."""
    import numpy as np
    (d / "myrep").mkdir()
    (d / "myrep" / "report.md").write_text("my discussion, written by hand\n")
    (d / "myrep" / "data.png").write_text(TENSILE_CSV)
    (d / "chdir").mkdir()
    (d / "chdir" / "summary.md").write_text(_CHAIN_STUDY)
    for name, edit in (("t_conf", lambda h: h.attrs.__setitem__("confidence", 2.0)),
                       ("t_nan", lambda h: h["f_eff_N_m3"].__setitem__(
                           Ellipsis, np.where(np.arange(h["f_eff_N_m3"].size).reshape(
                               h["f_eff_N_m3"].shape) == 4, np.nan, h["f_eff_N_m3"][()]))),
                       ("t_n", lambda h: h["n"].__setitem__(
                           Ellipsis, np.zeros(h["n"].shape, dtype=h["n"].dtype)))):
        shutil.copy(d / "table.h5", d / f"{name}.h5")
        with h5py.File(d / f"{name}.h5", "r+") as h:
            edit(h)
    for name, edit in (("r_msat", lambda f: f["m_sat_Am2"].__setitem__(0, -1.0)),
                       ("r_phi", lambda f: f.attrs.__setitem__("phi", 0.5))):
        shutil.copy(d / "rve.h5", d / f"{name}.h5")
        with h5py.File(d / f"{name}.h5", "r+") as f:
            edit(f)
    shutil.copy(d / "table.h5", d / "tside.h5")
    (d / "tside.manifest.json").mkdir()
    shutil.copy(d / "table.h5", d / "tparts.h5")
    (d / "tparts.parts").write_text("not a directory\n")
    (d / "dk_mesh").write_text("not the mesh directory of dk.sif\n")
    (d / "sd.manifest.json").mkdir()                  # where a side-car would be written


FIXTURE_HOOKS.append(_issue38_fixtures)

_TABLE_POINT = ("--phi", "0.01", "--B", "0.1", "--gradB", "1.78")
CASES += [
    # an output that is an input of the same run, through a directory option
    C("diagnose", "exp.toml", "--report", "myrep", "--discussion", "myrep/report.md",
      words=("myrep/report.md", "input", "--report")),
    C("diagnose", "e_inrep.toml", "--report", "myrep", words=("data.png", "input", "--report")),
    C("chain", "chdir/summary.md", "--out", "chdir", words=("summary.md", "input", "--out")),
    # values read back, validated like typed ones
    C("compare", "t_conf.h5", "0", "1", words=("t_conf.h5", "confidence", "(0, 1)")),
    C("compare", "t_nan.h5", "0", "1", words=("t_nan.h5", "f_eff_N_m3", "non-finite")),
    C("compare", "t_n.h5", "0", "1", words=("t_n.h5", "n must")),
    C("beam", "--table", "t_conf.h5", *_TABLE_POINT, words=("confidence", "(0, 1)")),
    C("export", "--to", "abaqus", "--table", "t_nan.h5", *_TABLE_POINT, "--out", "-",
      words=("t_nan.h5", "non-finite")),
    C("rve", "--load", "r_msat.h5", words=("r_msat.h5", "m_sat_Am2", ">= 0")),
    C("rve", "--load", "r_phi.h5", words=("r_phi.h5", "phi", "disagrees")),
    C("batch", "study.toml", "--out", "tside.h5", words=("tside.manifest.json", "regular file")),
    C("batch", "study.toml", "--out", "tparts.h5", words=("tparts.parts", "directory")),
    # no blocking open of anything that is not a regular file
    C("rve", "--load", "fifo", words=("fifo", "regular file")),
    C("homogenize", "fifo", "--json", "h.json", words=("fifo", "regular file")),
    C("relax", "fifo", "--json", "o.json", words=("fifo", "regular file")),
    C("compare", "fifo", "0", "1", words=("fifo", "regular file")),
    C("beam", "--table", "fifo", *_TABLE_POINT, words=("fifo", "regular file")),
    C("batch", "fifo", "--out", "t.h5", words=("fifo", "regular file")),
    C("chain", "fifo", "--out", "ch", words=("fifo", "regular file")),
    C("rve", "--n", "20", "--histogram", "fifo", words=("--histogram", "regular file")),
    C("diagnose", "e_fifo.toml", words=("fifo", "regular file")),
    C("diagnose", "exp.toml", "--report", "rr", "--discussion", "fifo",
      words=("--discussion", "regular file")),
    # geometry against the slender-body assumptions, both dimensions named
    C("beam", "--thickness-m", "1", "--model", "eb", words=("thickness_m = 1 m", "length_m")),
    C("beam", "--length-m", "3e-3", "--model", "eb", words=("thickness_m", "length_m = 0.003")),
    C("channel", "--c-m", "0.5", words=("c_m", "0.5 m", "a_m", "0.005")),
    C("channel", "--d-m", "1e-300", words=("d_m", "b_m")),
    C("channel", "--b-m", "0.01", words=("b_m", "0.01 m", "d_m")),
    C(*_EXPORT, "--deck", "cantilever", "--thickness-m", "0.5", "--out", "d.inp",
      words=("thickness_m", "length_m")),
    C(*_EXPORT, "--deck", "channel", "--c-m", "0.5", "--out", "d.inp", words=("c_m", "a_m")),
    C("paper", "--thickness-m", "1", "--quick", "--out", "pp", words=("thickness_m", "length_m")),
    C("chain", "s_chain.toml", "--thickness", "1", "--out", "ch",
      words=("thickness_m", "length_m")),
    # ambiguous inputs: refused with the choice to make
    C("rve", "--n", "20", "--histogram", "h_both.csv", words=("count", "weight", "ambiguous")),
    C("rve", "--n", "20", "--histogram", "h_dup.csv", words=("radius_m", "duplicate")),
    C("rve", "--n", "20", "--histogram", "h_none.csv", words=("count", "weight")),
    # implausible measurements
    C("diagnose", "e_empty.toml", words=("e_empty.csv", "no data rows")),
    C("diagnose", "e_long.toml", words=("row 3", "deflection_m", "length")),
    # nothing created before the input is validated (no --out directory left behind)
    C("chain", "study.toml", "--out", "ch", words=("B_T", "two values")),
    C("chain", "s_chain_relax.toml", "--out", "ch", words=("relax", "gradB_T_per_m")),
    C("chain", "s_chain_multi.toml", "--out", "ch", words=("law", "several")),
    C("rve-size", "s_rs_ok.toml", "--out", "rs", "--quantity", "zzz", words=("zzz",)),
    C("rve-size", "s_rs_ok.toml", "--out", "rs", "--component", "q", words=("component", "'q'")),
    # more members: a companion output (side-car, mesh directory) that is an input or a file
    C("batch", "sc.manifest.json", "--out", "sc.h5", words=("sc.manifest.json", "input")),
    C("export", "--to", "elmer", *_EXPORT[3:], "--deck", "cantilever", "--out", "dk.sif",
      words=("dk_mesh", "not a directory")),
    C("channel", "--wall-m", "1e-9", words=("wall_m", "b_m + c_m")),
    # an option that means nothing without another one: refused, never silently ignored
    C("export", "--to", "abaqus", "--table", "table.h5", *_TABLE_POINT, "--E-Pa", "2e6",
      "--deck", "cantilever", "--out", "d.inp", words=("--deck", "--table")),
    C("beam", "--model", "eb", "--E-from-table", words=("--E-from-table", "--table")),
    C("beam", "--model", "eb", "--phi", "0.01", words=("--phi", "--table or --magnet")),
    C("beam", "--model", "eb", "--remanence-T", "1.2", words=("--remanence-T", "--magnet")),
    C("channel", "--phi", "0.01", words=("--phi", "--table")),
    C("channel", "--table", "table.h5", words=("--table", "--target-gap-m")),
    C("channel", "--png", "x.png", words=("--png", "--flow-rate-m3-s")),
    C(*_EXPORT, "--thickness-m", "2e-3", "--out", "-", words=("--thickness-m", "--deck")),
    C(*_EXPORT, "--phi", "0.01", "--out", "-", words=("--phi", "--table")),
    C("diagnose", "e_amb.toml", words=("stress_MPa", "stress_Pa", "ambiguous")),
    C("diagnose", "exp.toml", "--json", "sd.json", words=("sd.manifest.json", "regular file")),
    C("rve", "--n", "20", "--out", "sd.h5", words=("sd.manifest.json", "regular file")),
    C("rve", "--n", "20", "--radius", "1e-6", words=("--radius", "--distribution monodisperse")),
    C("rve", "--n", "20", "--distribution", "monodisperse", "--radius", "1e-7", "--gsd", "2",
      words=("--gsd", "--radius", "ambiguous")),
    C("rve", "--n", "20", "--median-radius", "1e-8", "--mean-radius", "2e-8",
      words=("--mean-radius", "--median-radius", "ambiguous")),
    C("rve", "--n", "20", "--cluster-size", "5", words=("--cluster-size", "--arrangement clusters")),
    C("rve", "--load", "rve.h5", "--phi", "0.3", words=("--phi", "--load")),
    # two outputs of one run on the same file (a side-car, a file in an output directory)
    C("rve", "--n", "20", "--out", "rj.h5", "--json", "rj.manifest.json",
      words=("rj.manifest.json", "also given")),
    C("diagnose", "exp.toml", "--json", "dj.json", "--report", "dj.manifest.json",
      words=("dj.manifest.json", "--report")),
    C("diagnose", "exp.toml", "--json", "r9/report.md", "--report", "r9",
      words=("r9/report.md", "--report r9")),
]
STUDIES["sc.manifest.json"] = STUDY

# the specimen's laws from data and its 3D geometry (issue 34)
_SPEC_LIN = ("specimen", "--radius-m", "1e-3", "--length-m", "1.6e-3", "--law", "linear",
             "--chi", "1", "--shear-modulus-Pa", "1e5")
CASES += [
    C("specimen", "--shape", "cylinder", "--radius-m", "1e-3", "--length-m", "1.6e-3", "--law",
      "table", "--phi", "0.1", "--shear-modulus-Pa", "1e5", words=("--law table", "--table")),
    C("specimen", "--shape", "cylinder", "--radius-m", "1e-3", "--length-m", "1.6e-3", "--law",
      "rve", "--shear-modulus-Pa", "1e5", words=("--law rve", "--phi")),
    C("specimen", "--shape", "cylinder", "--radius-m", "1e-3", "--length-m", "1.6e-3", "--law",
      "rve", "--phi", "0.1", "--chi", "1", "--shear-modulus-Pa", "1e5",
      words=("--law rve", "--chi")),
    C(*_SPEC_LIN, "--shape", "cylinder", "--table", "t.h5", words=("--table", "--law table")),
    C(*_SPEC_LIN, "--shape", "cylinder", "--particle-material", "carbonyl-iron",
      words=("--particle-material", "--law rve")),
    C(*_SPEC_LIN, "--shape", "box", words=("--shape box", "--geometry 3d")),
    C("specimen", "--geometry", "3d", "--shape", "sphere", "--radius-m", "1e-3", "--law",
      "linear", "--chi", "1", "--shear-modulus-Pa", "1e5", words=("--geometry 3d", "sphere")),
    C(*_SPEC_LIN, "--geometry", "3d", "--shape", "box", "--n-boundary", "24",
      words=("--n-boundary", "3D")),
]

# export --deck: geometric nonlinearity and a magnet's varying load (issue 35 item 3)
_EXPORT_MAT = _EXPORT[:3] + _EXPORT[5:]
_DECK_MAGNET = ("--magnet", "cylinder", "--magnet-size", "10e-3", "5e-3", "--remanence-T", "1.2",
                "--magnet-position", "0.017", "0.0025", "-0.010")
CASES += [
    C(*_EXPORT, "--deck", "cantilever", "--nlgeom", "maybe", "--out", "d.inp",
      words=("--nlgeom", "maybe")),
    C(*_EXPORT, "--nlgeom", "on", "--out", "-", words=("--nlgeom", "--deck")),
    C("export", "--to", "elmer", *_EXPORT[3:], "--deck", "cantilever", "--nlgeom", "on",
      "--out", "d.sif", words=("--nlgeom on", "Elmer")),
    C(*_EXPORT_MAT, *_DECK_MAGNET, "--out", "-", words=("--magnet", "--deck")),
    C(*_EXPORT, "--deck", "cantilever", *_DECK_MAGNET, "--out", "d.inp",
      words=("--body-force-N-m3", "--magnet", "not both")),
    C(*_EXPORT_MAT, "--deck", "cantilever", *_DECK_MAGNET[:2], *_DECK_MAGNET[5:], "--out",
      "d.inp", words=("--magnet cylinder", "--magnet-size")),
    C(*_EXPORT, "--remanence-T", "1.2", "--out", "-", words=("--remanence-T", "--magnet")),
    C(*_EXPORT_MAT, "--deck", "channel", *_DECK_MAGNET, "--out", "d.inp",
      words=("--magnet", "cantilever")),
    C(*_EXPORT_MAT, "--deck", "cantilever", *_DECK_MAGNET[:-1], "0.0", "--out", "d.inp",
      words=("overlaps", "strip")),
    C(*_EXPORT_MAT, "--deck", "cantilever", *_DECK_MAGNET, "--table", "table.h5", "--phi",
      "0.01", "--B", "0.1", "--out", "d.inp", words=("--B", "--magnet")),
]

# the specimen on a plate above a magnet (issue 34): gaps, overlap, exclusive options
_SPEC_MAG = (*_SPEC_LIN, "--shape", "cylinder", "--magnet", "cylinder", "--magnet-size",
             "10e-3", "5e-3", "--remanence-T", "1.2")
CASES += [
    C(*_SPEC_MAG, "--gap-m", "0", words=("--gap-m", "> 0 m")),
    C(*_SPEC_MAG, "--gap-m=-1e-3", words=("--gap-m", "magnet into the specimen")),
    C(*_SPEC_MAG, "--gap-m", "2e-3:-1e-3:4", words=("--gap-m", "> 0 m")),
    C(*_SPEC_MAG, "--gap-m", "2e-3,3e-3", words=("--gap-m", "decrease strictly")),
    C(*_SPEC_MAG, "--gap-m", "2e-3,2e-3", words=("--gap-m", "decrease strictly")),
    C(*_SPEC_MAG, "--gap-m", "x", words=("--gap-m", "START:STOP:COUNT")),
    C(*_SPEC_MAG, "--gap-m", "3e-3", "--B", "0.2", words=("--B", "--magnet")),
    C(*_SPEC_MAG, words=("--magnet cylinder", "--gap-m")),
    C(*_SPEC_MAG[:-2], "--gap-m", "3e-3", words=("--magnet cylinder", "--remanence-T")),
    C(*_SPEC_MAG, "--gap-m", "3e-3", "--geometry", "3d", words=("--magnet", "axisymmetric")),
    C(*_SPEC_LIN, "--shape", "cylinder", "--gap-m", "3e-3", words=("--gap-m", "--magnet")),
    C(*_SPEC_LIN, "--shape", "cylinder", "--support", "plate", words=("--support", "--magnet")),
]


# --------------------------------------------------------------------------- running a case
def _snapshot(d: Path) -> dict:
    out = {}
    for p in sorted(d.rglob("*")):
        rel = str(p.relative_to(d))
        if p.is_symlink() or not (p.is_file() or p.is_dir()):
            out[rel] = "special"
        elif p.is_dir():
            out[rel] = "dir"
        else:
            out[rel] = hashlib.sha256(p.read_bytes()).hexdigest()
    return out


@dataclass
class Outcome:
    case: Case
    code: object
    stderr: str
    verdict: str
    detail: str = ""
    seconds: float = 0.0
    created: list = field(default_factory=list)


def prepare(case_dir: Path, fixtures: Path) -> None:
    shutil.copytree(fixtures, case_dir, dirs_exist_ok=True)
    os.mkfifo(case_dir / "fifo")


def _run_inprocess(case: Case, d: Path):
    from homogenize.cli import main
    err, out = io.StringIO(), io.StringIO()
    cwd = os.getcwd()
    os.chdir(d)
    try:
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(out):
            try:
                code = main(list(case.argv))
            except SystemExit as exc:
                code = exc.code
            except BaseException as exc:       # an escaped exception: a traceback
                import traceback
                traceback.print_exc(file=err)
                code = f"exception {type(exc).__name__}"
    finally:
        os.chdir(cwd)
    return code, err.getvalue()


def _limit_memory(nbytes: int):
    def set_limit():
        import resource
        resource.setrlimit(resource.RLIMIT_AS, (nbytes, nbytes))
    return set_limit


def _run_subprocess(case: Case, d: Path, pythonpath: str | None = None, timeout: float = 300,
                    memory_bytes: int | None = None):
    """``mapsim`` as a process; with ``pythonpath`` another source tree (the baseline), with a
    time and memory limit: a case that exceeds them is judged ``runaway``."""
    env = dict(os.environ, PYTHONWARNINGS="ignore")
    if pythonpath:
        env["PYTHONPATH"] = pythonpath
    try:
        p = subprocess.run([sys.executable, "-m", "homogenize.cli", *case.argv], cwd=d,
                           env=env, capture_output=True, text=True, timeout=timeout,
                           preexec_fn=_limit_memory(memory_bytes) if memory_bytes else None)
    except subprocess.TimeoutExpired:
        return "runaway", f"still running after {timeout:g} s"
    if memory_bytes and "MemoryError" in p.stderr:
        return "runaway", f"MemoryError above {memory_bytes / 2 ** 30:g} GiB\n" + p.stderr
    if p.returncode < 0:
        return "runaway", f"killed by signal {-p.returncode}"
    return p.returncode, p.stderr


def run_case(case: Case, case_dir: Path, fixtures: Path, baseline: str | None = None) -> Outcome:
    """Run ``case`` in ``case_dir`` (a fresh copy of ``fixtures``) and judge it; with
    ``baseline`` (a source tree), run it as a limited process on that code instead."""
    prepare(case_dir, fixtures)
    before = _snapshot(case_dir)
    t0 = time.perf_counter()
    if baseline:
        code, err = _run_subprocess(case, case_dir, baseline, timeout=120,
                                    memory_bytes=6 * 2 ** 30)
    else:
        code, err = (_run_subprocess if case.subprocess else _run_inprocess)(case, case_dir)
    dt = time.perf_counter() - t0
    after = _snapshot(case_dir)
    lost = [k for k, v in before.items() if after.get(k) != v
            and not (case.code == 0 and k in _RESULT_FILES)]
    created = [k for k in after if k not in before]
    allowed = set(case.creates)
    left = [k for k in created if k not in allowed]
    lines = [ln for ln in err.splitlines() if ln.strip()]
    o = Outcome(case, code, err, "clean", seconds=dt, created=created)
    if code == "runaway":
        o.verdict, o.detail = "runaway", err.splitlines()[0]
    elif "Traceback" in err or (isinstance(code, str) and code.startswith("exception")):
        o.verdict, o.detail = "traceback", (lines[-1] if lines else str(code))
    elif lost:
        o.verdict, o.detail = "lost", f"input changed or removed: {lost}"
    elif case.code != 0 and code == 0:
        o.verdict, o.detail = "silent", "exit 0 where a refusal was expected"
    elif code != case.code:
        o.verdict, o.detail = "wrong", f"exit {code}, expected {case.code}: " + \
            (lines[-1] if lines else "")
    elif case.code != 0:
        msg = lines[-1] if lines else ""
        want = f"mapsim {case.cmd}: error:"
        missing = [w for w in case.words if w.lower() not in msg.lower()]
        if len(lines) != 1 or not msg.startswith(want) or missing:
            o.verdict = "wrong"
            o.detail = (f"{len(lines)} lines; " if len(lines) != 1 else "") + \
                (f"missing words {missing}; " if missing else "") + msg[:200]
    if o.verdict == "clean" and left:
        o.verdict, o.detail = "left", f"files left behind: {left}"
    return o


# a successful run may rewrite these (the table and its side-car on resume)
_RESULT_FILES = {"table.h5", "table.manifest.json"}

VERDICTS = ("clean", "traceback", "silent", "wrong", "left", "lost", "runaway")


def run_all(work: Path, baseline: str | None = None) -> list:
    fixtures = build_fixtures(work / "fixtures")
    for name, text in STUDIES.items():          # the subprocess study, added after CASES
        (fixtures / name).write_text(text)
    out = []
    for i, c in enumerate(CASES):
        out.append(run_case(c, work / f"case{i:03d}", fixtures, baseline))
        shutil.rmtree(work / f"case{i:03d}", ignore_errors=True)
    return out


def _table(outcomes: list) -> list:
    by = {}
    for o in outcomes:
        by.setdefault(o.case.cmd, []).append(o)
    head = "| command | cases | " + " | ".join(VERDICTS) + " |"
    rows = [head, "|" + "---|" * (len(VERDICTS) + 2)]
    tot = {v: 0 for v in VERDICTS}
    for cmd, os_ in by.items():
        counts = {v: sum(o.verdict == v for o in os_) for v in VERDICTS}
        for v in VERDICTS:
            tot[v] += counts[v]
        rows.append(f"| {cmd} | {len(os_)} | " + " | ".join(str(counts[v]) for v in VERDICTS)
                    + " |")
    rows.append(f"| **all** | **{len(outcomes)}** | "
                + " | ".join(f"**{tot[v]}**" for v in VERDICTS) + " |")
    return rows


def report(outcomes: list, baseline: tuple | None = None) -> str:
    rows = _table(outcomes)
    bad = [o for o in outcomes if o.verdict != "clean"]
    n_ok = sum(o.case.code == 0 for o in outcomes)
    text = [
        "# Reliability: bad input, output safety, resume",
        "",
        "Written by `python tests/bad_input_cases.py` (the same table `tests/test_bad_input.py`",
        "runs); do not edit by hand. Each case runs `mapsim` in a fresh copy of the fixtures",
        "(an RVE and damaged copies of it, studies with one bad key each, a finished table,",
        "experiments with implausible data, a FIFO and a directory as output targets).",
        "",
        f"{len(outcomes)} cases: {len(outcomes) - n_ok} must be refused (exit 2, one line "
        f"`mapsim CMD: error: ...` naming the parameter, file, row or column and the allowed "
        f"range, before any work, no file written), {n_ok} must run (exit 0, only their own "
        f"outputs).",
        "",
        "Classes of cases: a value out of its range or of the wrong type (every option and "
        "study key); outputs that are inputs of the same run, devices, directories or too "
        "long, also through an output directory or a side-car manifest, and two outputs on "
        "one file; damaged or edited files read back (RVE files, tables, batch parts); "
        "inputs that are not regular files (a FIFO, /dev/zero, a directory: never opened); "
        "geometry against the slender-body assumptions of the beam and channel models; "
        "ambiguous inputs (two columns for one quantity, options that contradict each other "
        "or mean nothing without another); implausible measurements (units, empty data); "
        "runs too large for the machine; refusals that must leave nothing behind.",
        "",
        "Verdicts: **clean** as expected; **traceback** an exception reached the user; "
        "**silent** exit 0 where a refusal was due (silently wrong); **wrong** another exit "
        "code, more than one line, or a message missing the words; **left** files left "
        "behind; **lost** an input changed or disappeared; **runaway** (baseline only) killed "
        "after 120 s or 6 GiB.",
        "",
        *rows,
        "",
    ]
    if baseline:
        rev, base = baseline
        text += [f"### The same cases on the code before this work ({rev})", "",
                 "Run by `python tests/bad_input_cases.py --baseline REV` (the tree of REV from "
                 "`git archive`, each case a process limited to 120 s and 6 GiB; fixtures made "
                 "by the current code):", "", *_table(base), ""]
        worse = [o for o in base if o.verdict not in ("clean", "wrong")]
        if worse:
            text += ["Not clean before (tracebacks, silent, files left, data lost, runaway):", ""]
            text += [f"- `{o.case.id}`: {o.verdict} ({o.detail[:160]})" for o in worse]
            text += [""]
    if bad:
        text += ["## Not clean", ""]
        text += [f"- `{o.case.id}`: {o.verdict} ({o.detail})" for o in bad]
        text += [""]
    text += [
        "## Beyond the table (tests/test_bad_input.py)",
        "",
        "- batch resume: a zero-length and a truncated part are quarantined "
        "(`<table>.parts/quarantine/`) and recomputed; the table equals the uninterrupted one;",
        "- stale hidden temporary files `.NAME.*.tmp` of a killed run are removed by the next "
        "run (under an exclusive lock on the table, so none belongs to a live writer);",
        "- a side-car `<table>.manifest.json` that disagrees with the manifest inside the table "
        "(the authoritative one) is rewritten on the next run;",
        "- a deterministic error in an evaluator is evaluated once (not retried) and reported "
        "in one line; `--out` of another study's table is refused unless `--clean`;",
        "- the numba cache falls back to a private temporary directory only when neither the "
        "source tree nor the user cache can be written;",
        "- batch resume (issue 38): a part whose values are NaN, a part of another seed, a "
        "part with other quantities than the rest and a FIFO among the parts are quarantined "
        "(the FIFO never opened) and recomputed; the table equals the uninterrupted one;",
        "- the shared roots (tests/test_input_roots.py): `check_slender` (beam: length >= 4 x "
        "thickness; channel: d >= 4 b, c <= 10 a, wall >= 0.1 (b + c)), `check_header` (a "
        "repeated column, count and weight both given), `open_regular` (never blocks on a FIFO), "
        "inputs protected from the run's own atomic writes, `check_output_dir` (an input the "
        "run would write inside an output directory), `check_part`, `check_table` (an edited "
        "`confidence`, non-finite values).",
        "",
        "## Fault tolerance under load (results/reliability/fault_tolerance.md)",
        "",
        "`results/reliability/fault_tolerance.py` (reduced in "
        "`tests/homogenize/test_batch_faults.py`) runs a batch of 100 realizations (real RVEs, "
        "FEM on 8^3 voxels) on 2 worker processes while a worker is killed mid-task, the "
        "`mapsim batch` process (with its local scheduler) is killed, an external Dask "
        "scheduler is killed and restarted, and the table's file system (a size-limited tmpfs) "
        "fills up among the parts and at the table. Each faulted run finishes or ends in one "
        "line (exit 1; on a full disk naming the file it could not write), the same command "
        "then recomputes only the realizations in flight, nothing half-written is kept, and "
        "every final table is bitwise equal to an uninterrupted one-worker run.",
        "",
    ]
    return "\n".join(text)


_BASELINE_HEAD = "### The same cases on the code before this work"


def _keep_baseline(md: str, old: str) -> str:
    """A run without ``--baseline`` keeps the baseline section of the previous report (it
    describes the code of its revision, with the cases of that time, and takes long to make)."""
    if _BASELINE_HEAD not in old or _BASELINE_HEAD in md:
        return md
    start = old.index(_BASELINE_HEAD)
    end = old.find("\n## ", start)
    section = old[start:] if end < 0 else old[start:end + 1]
    at = md.find("\n## ")
    at = len(md) if at < 0 else at + 1
    return md[:at] + section.rstrip("\n") + "\n\n" + md[at:]


def main(argv=None) -> int:
    import argparse
    import tempfile
    ap = argparse.ArgumentParser(description="run the bad-input cases, write "
                                             "results/reliability.md")
    ap.add_argument("--baseline", default=None, metavar="REV",
                    help="also run every case on the code of git revision REV")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        outcomes = run_all(Path(tmp) / "now")
        base = None
        if args.baseline:
            tree = Path(tmp) / "tree"
            tree.mkdir()
            arch = subprocess.run(["git", "-C", str(ROOT), "archive", args.baseline],
                                  capture_output=True, check=True).stdout
            subprocess.run(["tar", "-x", "-C", str(tree)], input=arch, check=True)
            base = (args.baseline, run_all(Path(tmp) / "base", baseline=str(tree)))
    md = report(outcomes, base)
    out = ROOT / "results" / "reliability.md"
    if base is None and out.is_file():
        md = _keep_baseline(md, out.read_text(encoding="utf-8"))
    out.parent.mkdir(exist_ok=True)
    out.write_text(md, encoding="utf-8")
    print(md)
    return 0 if all(o.verdict == "clean" for o in outcomes) else 1


if __name__ == "__main__":
    sys.path.insert(0, str(ROOT))
    raise SystemExit(main())

# mapsim beam --gap-m G --follower-fem: the 3D neo-Hookean FEM with the field on the deformed
# body (issue 35 item 1)
_BEAM_GAP = ("beam", "--magnet", "cylinder", "--magnet-size", "10e-3", "10e-3", "--remanence-T",
             "1.3")
CASES += [
    C("beam", "--follower-fem", words=("--follower-fem", "--gap-m")),
    C(*_BEAM_GAP, "--gap-sweep-m", "0.02:0.01:3", "--follower-fem",
      words=("--follower-fem", "--gap-m")),
    C(*_BEAM_GAP, "--gap-m", "8e-3", "--follower-fem", "--png", "p.png",
      words=("--png", "--follower-fem")),
    C(*_BEAM_GAP[:-2], "--gap-m", "8e-3", "--follower-fem", words=("--magnet cylinder",
                                                                    "--remanence-T")),
    C("beam", "--magnet", "coil", "--magnet-size", "1e-2", "1e-2", "--current-A", "1",
      "--turns", "10", "--gap-m", "8e-3", "--follower-fem", words=("--gap-m", "permanent")),
    C(*_BEAM_GAP, "--gap-m=-1e-3", "--follower-fem", words=("--gap-m",)),
]
CASES += [
    C(*_BEAM_GAP, "--gap-m", "8e-3", "--follower-fem", "--nz", "1", "--json", "f.json", code=0,
      creates=("f.json",), note="the follower FEM at one gap: its tip deflection"),
]
