r"""A held-out validation set: seeded random fields that training never draws.

Training sample ``i`` of step ``t`` is drawn from ``np.random.default_rng([seed, t, i])`` (a three-word seed);
held-out field ``j`` of a stream comes from ``np.random.default_rng([VALIDATION_SEED + stream, j])`` (a two-word
seed; ``stream`` is 0 for validation and 1 for reports, :data:`rfmap.tasks.heldout.STREAMS`), a different random
stream for every ``seed``, ``t`` and ``i``.  The paper's test fields are never used to select a model; they are
reported beside the validation metric only.

The set mixes kinds, sharp ones included, so that folds show up during training:

* density tasks: ``smooth`` (a random training-style density without sharp parts), ``steps`` (box steps and
  high-frequency patches), ``peak`` (a narrow Gaussian peak of height 1–8 over a gently tilted background) and
  ``ramp`` (a steep tanh ramp of height 1–4 across a random direction); after the density preprocessing (minimum
  shifted to 0.1, an inference from the paper's Std(ρ̃_orig), see :mod:`rfmap.core.inputs`) their
  largest-to-smallest density ratios lie within those of the training fields (up to ~80);
* Beltrami tasks: random boundary-fixing maps (:class:`rfmap.fields.random.RandomMap`) with their exact image, at
  sup-norm levels of :math:`|\mu|` spread over [0.1, 0.85]; the metric is the mean vertex distance to the exact map.  A
  second set of low-frequency maps (1-4 slow modes) serves reports only.

The score of a density model is the mean over field families of each family's mean Std(ρ̃_map) relative to
the field's own Std(ρ̃_orig) (:func:`score`; the per-family values are ``families`` in the summary), with every
folded map counted as the identity map (ratio 1); the plain and penalized means over fields are kept in the summary.
The score of a Beltrami model is the mean vertex distance (``mean_dd``) with every folded map counted as the
identity map, i.e. as no map at all (``penalized``): a fold costs the model everything it gained on that field, and
no more.

With ``evaluate(..., repair=True)`` (``TrainConfig.val_repair``, the 3D models) the maps scored are those that
``Surrogate.map`` returns by default: a folded network map is first tried on coarser working grids and then
repaired, so a steep ramp that the network folds counts with the fold-free map a user would get rather than as the
identity.  A returned map that is worse than no map counts as the identity.  Why these rules, with the
measurements: the book's page :doc:`Design decisions </book/design>`.
"""
from __future__ import annotations

import numpy as np

from ..finish import quiet_quality
from ..tasks import get_task
from ..tasks.density import DENSITY_KINDS
from ..tasks.heldout import STREAMS, VALIDATION_SEED, ValidationField

__all__ = ["VALIDATION_SEED", "STREAMS", "ValidationField", "validation_fields", "evaluate", "score", "score_parts",
           "has_folds", "DENSITY_KINDS", "family", "family_table"]


def validation_fields(kind: str, dim: int, count: int = 16, stream: str = "validation",
                      low_frequency: bool = False) -> list[ValidationField]:
    """The fixed held-out set of a task (:meth:`rfmap.tasks.base.Task.validation_fields`): ``count`` fields (the density
    families in turn).  ``stream='validation'`` is the set used during training; ``stream='report'`` another set of
    the same kinds, used only to report generalization.  ``low_frequency`` (Beltrami only): random maps of 1-4 slow
    modes instead (``RandomBeltramiConfig.low_modes``, ``low_freq``; labels ``low-map-j``)."""
    if count < 1:
        raise ValueError(f"the validation set needs at least one field, got {count}")
    return get_task(kind).validation_fields(dim, count, stream, low_frequency)


def _held_out_map(sur, field, n: int, repair: bool = False, native: bool = False):
    with quiet_quality():
        return sur.map(field, n, repair=repair, native=native)


def _raw_folded(info: dict) -> bool:
    """Whether the network's own map was folded, from the report of a ``Surrogate.map(..., repair=True)`` call (a
    folded map is first tried on coarser working grids, ``info["regrid"]``, then repaired)."""
    return "regrid" in info or bool(info.get("repair", {}).get("needed", False))


def evaluate(sur, ns, count: int = 16, *, repair: bool = False, native: bool = False) -> dict:
    """Metrics of surrogate ``sur`` on the validation set at every grid side in ``ns``: of the raw network output
    (no refinement or repair; the default), or with ``repair`` of the map as ``Surrogate.map`` returns it by
    default (a folded network map tried on coarser working grids, then repaired: the map a user gets).  With
    ``native`` the network runs on each validation grid itself (``Surrogate.map(..., native=True)``), not on a
    working grid inside its training range.

    Returns
    -------
    dict
        ``{label@N: {metric: value}}`` per field and size, and ``"mean"``: the mean metric (``std_rho_map`` or
        ``mean_dd``), the total number of flipped elements, the smallest Jacobian determinant, ``folded_fields``
        (how many maps have a flipped element) and ``capped``: the mean metric with each folded map's value
        replaced by that of doing nothing (the identity map: Std(ρ̃_orig) of the field, or the identity's
        distance to the exact Beltrami map) when that is lower.  A folded map's Std(ρ̃_map) can be arbitrarily
        large (elements of almost zero measure), so the plain mean is at the mercy of one folded field; the capped
        mean counts a folded map as no better than no map (a map with non-finite points counts as folded).
        ``penalized``: the mean metric with each folded map's
        value replaced by that of the identity map (a folded map is worth no more than no map, even where its own
        value is lower); the selection score.  With ``repair`` the metrics are those of the default maps (and in
        ``penalized`` a default map that is worse than the identity counts as the identity), every record gains
        ``raw_folded`` (the network's own map was folded) and ``"mean"`` gains ``"path": "repaired"``
        and ``raw_folded_fields``.
    """
    spec, task = sur.spec, sur.spec.task
    fields = validation_fields(spec.kind, spec.dim, count)
    out: dict = {}
    primary, capped, penalized, flips, folded, min_j, raw_folded = [], [], [], 0, 0, np.inf, 0
    relative: dict[str, list[float]] = {}
    for n in ns:
        for vf in fields:
            r = _held_out_map(sur, vf.field, int(n), repair, native)
            rec, value, baseline = task.validation_record(r, vf)
            # a map with non-finite points (a diverged network) is no map either: counted as folded
            broken = bool(rec["n_flipped"]) or not np.isfinite(value)
            primary.append(value)
            capped.append(min(value, baseline) if broken else value)
            # default maps are fold-free; one that leaves the field less equal than it was (a repair can) is
            # worth no more than no map
            penalized.append(baseline if broken else (min(value, baseline) if repair else value))
            relative.setdefault(family(vf.label), []).append(penalized[-1] / baseline if baseline > 0 else 1.0)
            flips += int(rec["n_flipped"])
            folded += int(broken)
            min_j = min(min_j, float(rec["min_jacobian"]))
            if repair:
                rec["raw_folded"] = _raw_folded(r.info)
                raw_folded += int(rec["raw_folded"])
            out[f"{vf.label}@{n}"] = rec
    out["mean"] = {task.score_metric: float(np.mean(primary)), "n_flipped": flips, "min_jacobian": min_j,
                   "folded_fields": folded, "capped": float(np.mean(capped)), "penalized": float(np.mean(penalized))}
    if task.equalizes:  # every field counts relative to doing nothing: a score by field family
        fam = {k: float(np.mean(v)) for k, v in relative.items()}
        out["mean"].update(families=fam, family_score=float(np.mean(list(fam.values()))))
    if repair:
        out["mean"].update(path="repaired", raw_folded_fields=raw_folded)
    if native:
        out["mean"]["native"] = True
    return out


def family(label: str) -> str:
    """The field family of a validation label (``'ramp-3'`` → ``'ramp'``, ``'low-map-2'`` → ``'low-map'``)."""
    return label.rsplit("-", 1)[0]


def family_table(summary: dict) -> str:
    """The per-family scores of a validation summary (``evaluate(...)["mean"]``) as a one-line table for logs:
    ``smooth 0.21 | steps 0.30 | peak 0.42 | ramp 0.55 || score 0.37, 0 folded``."""
    fam = summary.get("families")
    if not fam:
        return ""
    cells = " | ".join(f"{k} {v:.3g}" for k, v in fam.items())
    return f"{cells} || score {summary['family_score']:.4g}, {summary.get('folded_fields', 0)} folded"


def score(summary: dict) -> tuple[int, float]:
    """Sort key of a validation summary (``evaluate(...)["mean"]``), lower is better: the first two entries of
    :func:`score_parts`.

    Density models: ``(0, family_score)``, the mean over field families (smooth, steps, peak, ramp) of each
    family's mean of Std(ρ̃_map) / Std(ρ̃_orig), a folded map counted as the identity (ratio 1).  Every family
    weighs the same and every field counts relative to doing nothing, so the few steep ramps, whose Std is several
    times the others', cannot decide the choice alone.  Beltrami models: ``(0, penalized)``, the mean vertex
    distance with a folded map counted as the identity (see :func:`evaluate`).

    A summary that lacks these entries (one recorded by an earlier version of the package) ranks after every summary
    that has them."""
    # summaries written before these entries existed: (1, penalized), a fold-free one (1, mean), one with a folded
    # map, whose penalized mean is unknown, (2, capped mean)
    tier, value, _ = score_parts(summary)
    return tier, value


def has_folds(summary: dict, raw: bool = False) -> bool:
    """Whether a validation summary's maps folded on some held-out field: its ``folded_fields`` count, or in older
    summaries, which do not record it, its ``n_flipped`` count of flipped elements.  With ``raw``, whether the
    network's raw map folded: the ``raw_folded_fields`` count where the summary scored the repaired map
    (``evaluate(..., repair=True)``), else the same count."""
    if raw and "raw_folded_fields" in summary:
        return (summary["raw_folded_fields"] or 0) > 0
    return (summary.get("folded_fields", summary.get("n_flipped")) or 0) > 0


def score_parts(summary: dict) -> tuple[int, float, str]:
    """:func:`score`'s tier and value of a validation summary, and which entry the value is: ``"family_score"``,
    ``"penalized"``, ``"capped"`` or ``"mean"`` (the plain mean metric, ``mean_dd`` or ``std_rho_map``)."""
    key = "mean_dd" if "mean_dd" in summary else "std_rho_map"
    if "family_score" in summary:
        return 0, float(summary["family_score"]), "family_score"
    if "penalized" in summary:
        return (0 if key == "mean_dd" else 1), float(summary["penalized"]), "penalized"
    if not has_folds(summary):
        return (0 if key == "mean_dd" else 1), float(summary[key]), "mean"
    if "capped" in summary:
        return 2, float(summary["capped"]), "capped"
    return 2, float(summary[key]), "mean"
