"""Shared test configuration: single-threaded torch and BLAS, so that the tests stay fast beside other jobs.

Multi-threaded OpenBLAS on an oversubscribed machine can make a single small call (e.g. the first
``scipy.interpolate.griddata``) take seconds, so the BLAS thread pools are limited before numpy is imported
(``setdefault``: an explicit setting in the environment wins).  Subprocesses started by the tests inherit this.
"""
import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import torch  # noqa: E402

torch.set_num_threads(1)
