"""Compare or update ``tests/data/reference_outputs.npz``: the outputs that ``tests/test_reference_outputs.py``
compares against.

Usage::

    python scripts/make_reference_outputs.py                      # compare only: print the differing keys
    python scripts/make_reference_outputs.py --only 'flow-*/*'    # rewrite the keys matching these patterns
    python scripts/make_reference_outputs.py --make-models        # write the tiny networks missing from tests/data

Every run computes the outputs and prints, for each key that is not bit for bit its stored array, the largest
absolute and relative difference and whether it is within the test's tolerance.  Only the keys named with ``--only``
(exact keys or ``fnmatch`` patterns such as ``'sur-polish/*'``) are written: added, replaced, or removed when they are
no longer produced; every other stored array is kept bit for bit, however much it now differs, so that changing one
output cannot silently re-freeze the others.  Without ``--only`` nothing is written, except when the file does not
exist yet (then every key is).

The surrogate references use the frozen tiny networks ``tests/data/tiny-*.safetensors`` (never the shipped weights,
which are retrained).  ``--make-models`` writes those that are missing, each the ``ci`` preset's network trained
:data:`TINY_STEPS` steps from a fixed seed; it never overwrites one, because every surrogate reference depends on
them: to replace a network, delete its file and rewrite its keys with ``--only 'sur*/tiny-NAME/*'``.
"""
from __future__ import annotations

import argparse
import importlib.util
import os
import sys
import tempfile
from fnmatch import fnmatch
from pathlib import Path

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
TESTS = ROOT / "tests"

#: The frozen tiny networks: file name -> (training configuration of the ``ci`` preset, steps).  Trained with a raised
#: learning rate (1e-2) and seed 0, so that their maps equalize a little (Std(rho~_map) about 0.6-0.9 of the input's
#: at N = 17 and 9) and the default path's repair and shortening have a map worth repairing.
TINY_STEPS = {"tiny-deq2d-square": ("deq2d-square", 200), "tiny-deq2d-free": ("deq2d-free", 200),
              "tiny-beltrami2d": ("beltrami2d", 200), "tiny-dem3d-cube": ("dem3d-cube", 300),
              "tiny-dem3d-free": ("dem3d-free", 200)}


def load_test_module():
    """``tests/test_reference_outputs.py`` as a module (its functions make the outputs)."""
    spec = importlib.util.spec_from_file_location("test_reference_outputs", TESTS / "test_reference_outputs.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def make_tiny_models(data_dir: Path = TESTS / "data") -> list[Path]:
    """Train and write each network of :data:`TINY_STEPS` that ``data_dir`` lacks; returns the files written."""
    import torch

    import rfmap.training as T
    from rfmap.training.config import get_config
    from rfmap.surrogate import Surrogate

    written = []
    for name, (config, steps) in TINY_STEPS.items():
        path = data_dir / f"{name}.safetensors"
        if path.exists():
            print(f"{path.relative_to(ROOT)}: kept (never overwritten)")
            continue
        cfg = get_config(config, "ci").with_overrides(steps=steps, lr=1e-2, seed=0, threads=1, workers=0,
                                                      val_every=10**6, ckpt_every=10**6)
        with tempfile.TemporaryDirectory() as tmp:
            sur = T.train(cfg, tmp, progress=False)
        meta = {"name": name, "n_range": list(cfg.n_range), "steps": steps, "seed": 0,
                "command": f"rfmap train --config {config} --preset ci --steps {steps} --lr 0.01 --seed 0",
                "torch_version": torch.__version__}
        Surrogate(sur.model, sur.spec, meta).save(path)
        written.append(path)
        print(f"{path.relative_to(ROOT)}: trained {steps} steps of {config} (ci)")
    return written


def differences(stored: dict[str, np.ndarray], now: dict[str, np.ndarray], matches) -> list[tuple]:
    """``(key, status, largest absolute difference, largest relative difference)`` for every key that is not bit for
    bit its stored array, largest relative difference first; status is ``new``, ``gone``, ``shape``, ``within
    tolerance`` or ``DIFFERS``."""
    rows = []
    for k in sorted(set(stored) | set(now)):
        if k not in stored:
            rows.append((k, "new", np.nan, np.nan))
        elif k not in now:
            rows.append((k, "gone", np.nan, np.nan))
        elif np.shape(stored[k]) != np.shape(now[k]):
            rows.append((k, "shape", np.nan, np.nan))
        elif not np.array_equal(stored[k], now[k], equal_nan=True):
            a = np.asarray(now[k], dtype=np.complex128 if np.iscomplexobj(now[k]) else np.float64)
            b = np.asarray(stored[k], dtype=a.dtype)
            d = np.abs(a - b)
            d = d[~np.isnan(d)]
            big = float(d.max(initial=0.0))
            rel = big / max(float(np.nanmax(np.abs(b), initial=0.0)), 1e-300)
            rows.append((k, "within tolerance" if matches(k, now[k], stored[k]) else "DIFFERS", big, rel))
    order = {"DIFFERS": 0, "shape": 0, "gone": 1, "new": 1, "within tolerance": 2}
    return sorted(rows, key=lambda r: (order[r[1]], -np.nan_to_num(r[3], nan=0.0), r[0]))


def update(path: Path, now: dict[str, np.ndarray], only: list[str]) -> list[str]:
    """Write to ``path`` the keys matching a pattern of ``only`` (added, replaced, or removed when ``now`` lacks them)
    and keep every other stored array as it is; returns the keys written or removed.  A pattern that matches no key
    is an error (``ValueError``) and nothing is written."""
    with np.load(path) as z:
        stored = {k: z[k] for k in z.files}
    keys = set(stored) | set(now)
    for pat in only:
        if not any(fnmatch(k, pat) for k in keys):
            raise ValueError(f"--only {pat!r} matches no key")
    named = sorted(k for k in keys if any(fnmatch(k, pat) for pat in only))
    out = dict(stored)
    for k in named:
        if k in now:
            out[k] = now[k]
        else:
            out.pop(k, None)
    tmp = path.with_name(path.name + ".part.npz")
    np.savez_compressed(tmp, **out)
    os.replace(tmp, path)
    return named


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--only", nargs="+", default=None, metavar="KEY",
                   help="write only these keys (exact keys or fnmatch patterns, e.g. 'flow-square/*')")
    p.add_argument("--make-models", action="store_true",
                   help="first train and write the tiny networks missing from tests/data (never overwrites)")
    args = p.parse_args(argv)
    import torch

    torch.set_num_threads(1)  # as in tests/conftest.py
    if args.make_models:
        make_tiny_models()
    mod = load_test_module()
    now = mod.reference_outputs()
    path = mod.DATA
    if not path.exists():
        path.parent.mkdir(parents=True, exist_ok=True)
        np.savez_compressed(path, **now)
        print(f"{path.relative_to(ROOT)}: {len(now)} arrays (new file), {path.stat().st_size / 1024:.0f} KiB")
        return 0
    with np.load(path) as z:
        stored = {k: z[k] for k in z.files}
    rows = differences(stored, now, mod.matches)
    named = set()
    if args.only:
        keys = set(stored) | set(now)
        named = {k for k in keys if any(fnmatch(k, pat) for pat in args.only)}
    for k, status, big, rel in rows:
        mark = "write" if k in named else ("keep" if args.only else "")
        print(f"{k:48s} {status:16s} max |diff| {big:10.3g}  relative {rel:10.3g}  {mark}")
    same = len(stored.keys() & now.keys()) - sum(r[1] not in ("new", "gone") for r in rows)
    print(f"{same} of {len(now)} produced arrays are bit for bit their stored ones")
    if not args.only:
        if rows:
            print("nothing written: name the keys to rewrite with --only KEY ... (patterns allowed)")
        return 0
    try:
        written = update(path, now, args.only)
    except ValueError as e:
        print(f"error: {e}; nothing written", file=sys.stderr)
        return 2
    kept = [r[0] for r in rows if r[0] not in named and r[1] != "within tolerance"]
    print(f"{path.relative_to(ROOT)}: wrote {len(written)} named key(s); kept {len(kept)} differing key(s) that were "
          f"not named{': ' + ', '.join(kept[:10]) if kept else ''}{' ...' if len(kept) > 10 else ''}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
