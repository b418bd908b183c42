"""The models the book's chapters use: shipped weights at ``full`` scale, tiny models trained on the spot at ``ci``.

A user's own code needs none of this: :meth:`rfmap.Surrogate.pretrained` loads a shipped model.
"""
from __future__ import annotations

import tempfile
from pathlib import Path

from .training.config import get_config, scale
from .surrogate import Surrogate

__all__ = ["load_or_train", "STUDY_WEIGHTS", "study_models"]

#: weights trained for one of the book's studies (an ablation, an equal-budget partner), not offered as models:
#: ``NAME.safetensors`` and ``NAME.json`` from ``rfmap train --config NAME --preset full``
STUDY_WEIGHTS = Path(__file__).resolve().parent / "data" / "studies" / "weights"


def study_models() -> list[str]:
    """The names of the study weights (:data:`~rfmap.pretrained.STUDY_WEIGHTS`), each a training config's name."""
    return sorted(p.stem for p in STUDY_WEIGHTS.glob("*.json") if p.with_suffix(".safetensors").exists())


def load_or_train(name: str, preset: str | None = None, *, out_dir=None, progress: bool = False) -> Surrogate:
    """The model a chapter of the book uses: the shipped weights at ``full`` scale (a shipped model's, or else a
    study's, :data:`~rfmap.pretrained.STUDY_WEIGHTS`); at ``ci`` scale a tiny model trained on the spot with the
    named configuration's ``ci`` preset (seconds; cached in the temporary directory and reused while the
    configuration is unchanged), so every notebook runs end to end on a laptop CPU.  The :term:`scale` is the
    ``RFMAP_SCALE`` setting that :func:`rfmap.training.config.scale` reads, and ``preset`` defaults to it; a
    preset is a configuration's settings at one scale (:mod:`rfmap.training.config`)."""
    preset = preset or scale()
    if preset == "full":
        if name in study_models():
            return Surrogate.load(STUDY_WEIGHTS / f"{name}.safetensors")
        return Surrogate.pretrained(name)
    cfg = get_config(name, preset)
    out = Path(out_dir or Path(tempfile.gettempdir()) / "rfmap-ci-models" / name)
    weights = out / f"{name}.safetensors"
    if weights.exists():  # trained earlier with the same configuration (training is seeded): reuse it
        try:
            cached = Surrogate.load(weights)
            if cached.meta.get("config") == cfg.to_dict():
                return cached
        except (ValueError, FileNotFoundError):
            pass
    from .training import train  # training code is needed only here, at ci scale

    return train(cfg, out, progress=progress)
