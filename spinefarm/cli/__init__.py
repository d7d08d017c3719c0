"""spinefarm cli."""

import os

# One BLAS thread per process unless the user says otherwise: a run's parallelism is its processes (workers, the
# coordinator, the judge), and OpenBLAS threads competing with them for the same cores made a CMA-ES proposal in
# 200 dimensions ~20x slower (docs/performance.md, "The coordinator's own cost"). Set before numpy loads.
for _name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_name, "1")
