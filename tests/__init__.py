"""trackctl's test suite (imported before its conftest and any numerical library)."""

import os

# pytest-xdist runs a worker per core: each keeps to one BLAS/OpenMP thread, or every worker
# would start a thread per core and they would fight over the same cores
for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")
