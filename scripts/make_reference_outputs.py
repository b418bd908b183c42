"""Write ``tests/data/reference_outputs.npz``: the outputs that ``tests/test_reference_outputs.py`` compares against.

Run it once at a commit whose outputs are the reference (``python scripts/make_reference_outputs.py``); a
restructuring of the package must then reproduce them.
"""
from __future__ import annotations

import importlib.util
import os
from pathlib import Path

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402
import torch  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    torch.set_num_threads(1)  # as in tests/conftest.py
    spec = importlib.util.spec_from_file_location("test_reference_outputs", ROOT / "tests" / "test_reference_outputs.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    arrays = mod.reference_outputs()
    mod.DATA.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(mod.DATA, **arrays)
    print(f"{mod.DATA.relative_to(ROOT)}: {len(arrays)} arrays, {mod.DATA.stat().st_size / 1024:.0f} KiB")


if __name__ == "__main__":
    main()
