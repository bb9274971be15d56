"""mapsim.micro.common: the neutral base that every layer of both packages stands on.

No physics here, and no import of any other project module: input validation and the errors
with their exit codes (:mod:`micro.common.validate`), atomic file output, manifests and result
digests (:mod:`micro.common.files`), progress bars (:mod:`micro.common.progress`), the serial
and parallel compilation of a numba kernel (:mod:`micro.common.jit`) and the choice of a
writable numba cache (:mod:`micro.common.numba_cache`). The project's top level is fixed
(``micro/`` and ``homogenize/``), so the base lives here, below the particle scale; the import
contract (tests/test_import_contract.py) keeps it at the bottom.
"""
