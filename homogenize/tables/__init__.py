"""Batch runs of many random RVEs and the effective-parameter tables they produce.

A study file (:mod:`homogenize.tables._study`: TOML, parsed and validated into a frozen
:class:`Study`) is a grid of conditions times random realizations; each realization is
evaluated (``_evaluate``: placement, dipoles, cell FEM or relaxation) on Dask and aggregated into
a table with Student-t intervals (``_stats``) widened by the discretization error
(:mod:`homogenize.tables.resolution`); :mod:`homogenize.tables.batch` runs the batch and reads
the table (HDF5, an xarray grid).
"""
from homogenize.tables.batch import (BatchError, Estimate, StorageError, Table, aggregate,
                                     body_force_from_table, dask_client, interpolate, modulus_from_table,
                                     parts_dir_for, read_table, run_batch)
from homogenize.tables._study import Study, load_study, parse_study

__all__ = ["run_batch", "aggregate", "read_table", "Table", "Estimate", "BatchError",
           "StorageError", "parts_dir_for", "interpolate", "body_force_from_table",
           "modulus_from_table", "dask_client", "Study", "load_study", "parse_study"]
