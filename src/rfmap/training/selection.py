r"""Choosing among saved weights after training: ``rfmap validate``.

A run on a GPU machine does not validate while it trains (``rfmap train --no-validate --snapshot-every K``);
it writes self-contained snapshots (weights with their metadata in the file's header,
``Surrogate.save(..., embed=True)``).  Back on a CPU, :func:`score_weights` scores each on the held-out validation
stream of its own configuration (:func:`rfmap.training.validation.evaluate` at the configuration's ``val_ns``,
``val_count`` and ``val_repair``) and :func:`ship_best` writes the best one as a shipped pair ``NAME.safetensors`` +
``NAME.json`` whose metadata records the validation, the file it was chosen from and its rivals.  The choice uses
:func:`rfmap.training.validation.score`, never the paper's test fields.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from ..finish import quiet_quality
from ..surrogate import Surrogate
from .validation import evaluate, family_table, score

__all__ = ["Scored", "weight_files", "score_weights", "ship_best", "scores_table"]


@dataclass
class Scored:
    """One scored weight file: its path, the loaded surrogate, the validation summary and its sort key."""

    path: Path
    surrogate: Surrogate
    validation: dict
    key: tuple

    @property
    def summary(self) -> dict:
        return self.validation["mean"]


def weight_files(paths) -> list[Path]:
    """The ``.safetensors`` files named by ``paths`` (files, or folders searched recursively), sorted; ``ValueError``
    when a path does not exist or names no weight file."""
    out: list[Path] = []
    for p in map(Path, paths):
        if p.is_dir():
            found = sorted(p.rglob("*.safetensors"))
            if not found:
                raise ValueError(f"no .safetensors weight file under {p}")
            out += found
        elif p.is_file():
            if p.suffix != ".safetensors":
                raise ValueError(f"{p} is not a .safetensors weight file")
            out.append(p)
        else:
            raise ValueError(f"no such file or folder: {p}")
    if not out:
        raise ValueError("no weight file given")
    return out


def _val_settings(meta: dict, count: int | None, sizes: tuple[int, ...] | None,
                  native: bool | None = None) -> tuple[tuple[int, ...], int, bool, bool]:
    cfg = meta.get("config") or {}
    ns = tuple(sizes or cfg.get("val_sizes") or ()) or (int(cfg.get("val_n", 51)),)
    nat = bool(cfg.get("val_native", False)) if native is None else bool(native)
    return ns, int(count or cfg.get("val_count", 16)), bool(cfg.get("val_repair", False)), nat


def score_weights(paths, *, count: int | None = None, sizes: tuple[int, ...] | None = None,
                  native: bool | None = None, progress: bool = True) -> list[Scored]:
    """Load and score every weight file of ``paths`` on its configuration's validation set (``count`` fields at grid
    sides ``sizes`` override it; ``native`` True/False overrides whether the network runs on each validation grid
    itself, :func:`rfmap.training.validation.evaluate`); all files must solve the same task.  Returns them best first."""
    files = weight_files(paths)
    surs = [Surrogate.load(p) for p in files]
    specs = {s.spec for s in surs}
    if len(specs) > 1:
        raise ValueError(f"the weight files solve different tasks: {sorted(map(str, specs))}")
    it = zip(files, surs)
    if progress:
        from tqdm.auto import tqdm

        it = tqdm(list(it), desc="validate", unit="file")
    scored = []
    with quiet_quality():
        for path, sur in it:
            ns, k, repair, nat = _val_settings(sur.meta, count, sizes, native)
            v = evaluate(sur, ns, k, repair=repair, native=nat)
            scored.append(Scored(path, sur, v, score(v["mean"])))
    return sorted(scored, key=lambda s: s.key)


def scores_table(scored: list[Scored]) -> str:
    """A plain-text table of scored files (best first): file, step, score, folded fields and the families."""
    lines = []
    for s in scored:
        step = s.surrogate.meta.get("snapshot_step", s.surrogate.meta.get("steps", "?"))
        fam = family_table(s.summary) or f"score {s.key[1]:.4g}, {s.summary.get('folded_fields', 0)} folded"
        lines.append(f"{s.path.name}  step {step}:  {fam}")
    return "\n".join(lines)


def ship_best(scored: list[Scored], out_dir, name: str | None = None) -> tuple[Path, Path]:
    """Write the best of ``scored`` to ``out_dir/NAME.safetensors`` + ``.json`` (``NAME``: the configuration's
    name), its metadata gaining ``final_metrics`` (its validation), ``selected_from`` (the file) and
    ``candidates`` (every file's score)."""
    if not scored:
        raise ValueError("nothing to ship: no scored weight file")
    best = scored[0]
    sur = best.surrogate
    sur.meta["final_metrics"] = best.validation
    sur.meta["selected_from"] = best.path.name
    sur.meta["selected_step"] = sur.meta.get("snapshot_step", sur.meta.get("selected_step"))
    sur.meta["candidates"] = [{"file": s.path.name, "score": list(s.key)} for s in scored]
    name = name or sur.meta.get("name") or best.path.stem
    return sur.save(Path(out_dir) / f"{name}.safetensors")
