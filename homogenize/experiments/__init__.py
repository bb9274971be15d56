"""Measured data, the seed model, causes and their extensions, and ``diagnose``.

* :func:`load_experiment` -- read and validate an experiment (TOML + CSV, see
  ``examples/data/EXPERIMENT_FORMAT.md`` in the project); :func:`write_experiment` writes one.
* :func:`seed_predict` -- the seed model of each kind.
* :data:`CAUSES`, :class:`ModelSpec`, :func:`predict` -- the causes' vocabulary and the seed
  model composed with any set of extensions.
* :func:`diagnose` -- cross-validated forward selection of causes; ``Diagnosis.as_dict()`` is
  the spec's JSON; :func:`write_report` its Markdown + PNG report.
* :func:`generate` -- seeded synthetic experiments with hidden causes; :func:`run_study`.
* :mod:`~homogenize.experiments.rve_tables` -- the precomputed RVE physics the extensions
  interpolate in (FEM filler stiffness, dipolar virial stress), re-made by
  ``mapsim diagnose-tables``.
"""
from homogenize.experiments.causes import CAUSES, DESCRIPTIONS, ModelSpec, applicable, predict
from homogenize.experiments.diagnose import Diagnosis, diagnose
from homogenize.experiments.io import Experiment, Matrix, Particles, Setup, load_experiment, write_experiment
from homogenize.experiments.report import write_report
from homogenize.experiments.seed_model import seed_body_force_N_m3, seed_predict
from homogenize.experiments.study import run_study, summarize
from homogenize.experiments.synthetic import CASES, SyntheticCase, generate, write_case

__all__ = ["CAUSES", "DESCRIPTIONS", "ModelSpec", "applicable", "predict", "Diagnosis",
           "diagnose", "Experiment", "Matrix", "Particles", "Setup", "load_experiment",
           "write_experiment", "write_report", "seed_body_force_N_m3", "seed_predict",
           "run_study", "summarize", "CASES", "SyntheticCase", "generate", "write_case"]
