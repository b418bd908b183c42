r"""Judging a density map: does it make the density more equal, and a warning when it does not.

A density map makes the density *more equal* when it lowers :math:`\mathrm{Std}(\tilde\rho)`, the spread of the
normalised element densities: :math:`\mathrm{Std}(\tilde\rho_{\text{map}})` on the mapped mesh below
:math:`\mathrm{Std}(\tilde\rho_{\text{orig}})` on the reference mesh (the :term:`judge`); it leaves the density
*less equal* when it raises it.  A map that raises it by more than the fraction :data:`QUALITY_MARGIN` is worse than
no map, and one that does not lower it by at least the fraction :data:`GAIN_RTOL` brought no gain
(:func:`density_quality`); :class:`PoorMapWarning` says so with the numbers and the remedies (:func:`quality_message`,
:func:`poor_map_message`), and :func:`quiet_quality` silences it where the metrics are reported anyway.
"""
from __future__ import annotations

import contextlib
import math
import warnings
from typing import Any

import numpy as np
import torch

from ..core.geometry import grid_element_mean, grid_signed_measures
from ..core.metrics import density_std
from ..solvers.flow import F32_MARGIN
from .report import MapReport

__all__ = ["QUALITY_MARGIN", "GAIN_RTOL", "PoorMapWarning", "quiet_quality", "density_quality", "quality_message",
           "poor_map_message"]

#: :func:`density_quality` calls a map worse than the input when its Std(ρ̃_map) exceeds Std(ρ̃_orig) by more
#: than this fraction, far above the relative error of the single-precision measures.  For a near-uniform input,
#: whose spread (and so the margin it sets) is near zero, the absolute 1e-5 of :func:`density_quality` covers the
#: round-off instead; between them, the identity never counts as worse
QUALITY_MARGIN = 1e-4

#: :func:`density_quality` says a map brought no gain when it lowered Std(ρ̃) by less than this fraction of
#: Std(ρ̃_orig): the identity, whose two spreads differ only by round-off, is always such a map
GAIN_RTOL = 1e-3


class PoorMapWarning(RuntimeWarning):
    r"""A density map that did not make the density more equal (:func:`density_quality`); issued by
    :meth:`rfmap.Surrogate.map` and :func:`rfmap.finish.pipeline.finish_map` with the measured numbers and the remedies.

    The check has a stated relative tolerance :math:`t` = :data:`GAIN_RTOL` (one in a thousand): a map is flagged
    unless :math:`\mathrm{Std}(\tilde\rho_{\text{map}}) < (1 - t)\,\mathrm{Std}(\tilde\rho_{\text{orig}})`, and
    also when it had to be shortened (:func:`rfmap.finish.shorten.shorten_map`).  The identity map of a density that
    is not uniform is therefore flagged on every grid: its two spreads are equal up to round-off, which lies far
    inside the tolerance.
    """


@contextlib.contextmanager
def quiet_quality():
    """Silence :class:`PoorMapWarning` inside the block: for code that maps many fields and reports their metrics
    itself (tables, validation)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", PoorMapWarning)
        yield


def density_quality(mapped: np.ndarray, density: np.ndarray, n: int) -> dict[str, Any]:
    r"""Whether a density map of the ``N``-grid left the density more equal than it was.

    :math:`\mathrm{Std}(\tilde\rho)` of the element densities (population over measure, normalised to mean 1; as
    :func:`rfmap.core.metrics.compute_metrics`) on the reference and on the mapped grid, and the smallest Jacobian
    determinant (mapped over reference measure).

    Parameters
    ----------
    mapped : ndarray, shape (N**d, d)
        The images of the grid's vertices (:func:`rfmap.core.mesh.grid_points` order); every reference element has
        the same measure, so the reference vertices themselves are not needed.
    density : ndarray, shape (N**d,)
        Vertex densities.
    n : int
        Grid side.

    Returns
    -------
    dict
        ``std_rho_orig``, ``std_rho_map``, ``min_jacobian``; ``worse``: whether Std(ρ̃_map) exceeds
        ``(1 + QUALITY_MARGIN) * Std(ρ̃_orig) + 1e-5`` or the map is not finite, i.e. the map undid more than it
        did (the relative :data:`QUALITY_MARGIN` covers the single-precision round-off of a large spread, the
        absolute 1e-5 that of a near-uniform input, whose spread is near zero); and ``no_gain``: whether
        Std(ρ̃_map) is not below ``(1 - GAIN_RTOL) * Std(ρ̃_orig)`` (:data:`GAIN_RTOL`; or the map is not finite), i.e. the map did not make
        the density measurably more equal.  A map that is worse brings no gain; the identity brings none either, on
        every grid, whatever the round-off of the two spreads.
    """
    d = mapped.shape[1]
    if not np.isfinite(mapped).all():
        return {"std_rho_orig": float("nan"), "std_rho_map": float("nan"), "min_jacobian": float("nan"),
                "worse": True, "no_gain": True}
    # every element of the N-grid has the same reference measure; the mapped measures in single precision (faster;
    # book: Design decisions) unless an element is too thin for it (as rfmap.solvers.flow.F32_MARGIN)
    ref_measure = 1.0 / ((n - 1) ** d * math.factorial(d))
    meas = grid_signed_measures(torch.from_numpy(np.ascontiguousarray(mapped, dtype=np.float32))[None], n)[0].double()
    if float(meas.min()) <= F32_MARGIN * ref_measure:
        meas = grid_signed_measures(torch.from_numpy(np.ascontiguousarray(mapped, dtype=np.float64))[None], n)[0]
    mean = grid_element_mean(torch.as_tensor(np.asarray(density, dtype=np.float64)).reshape(1, -1), n, d)[0]
    orig = float((mean / mean.mean()).std())  # density_std with equal measures
    new = density_std(mean * ref_measure, meas)
    return {"std_rho_orig": orig, "std_rho_map": new, "min_jacobian": float(meas.min()) / ref_measure,
            "worse": bool(not new <= orig * (1.0 + QUALITY_MARGIN) + 1e-5),  # float32 round-off: ~1e-6
            "no_gain": bool(not new < orig * (1.0 - GAIN_RTOL))}


def quality_message(quality: dict[str, Any], refine: str = "refine=True", polish: str = "polish=True",
                    shorten: dict[str, Any] | None = None, *, grid_only: bool = False) -> str:
    """One line for a density map that left the density less equal than it was (:func:`density_quality`);
    ``refine`` and ``polish`` name the two remedies (the API's keywords by default, the CLI's flags there), and
    ``grid_only`` says that the second one maps a grid only (a map at query points).  With ``shorten`` (the report
    of :func:`rfmap.finish.shorten.shorten_map`) the line says that the map was shortened and what it reaches now."""
    finish = "the flow-based finish, on a grid only" if grid_only else "the flow-based finish"
    if shorten is not None:
        before = shorten["std_before"]
        return (f"the network's map left this density less equal than it was (Std(ρ̃_map) "
                f"{'folded' if not math.isfinite(before) else format(before, '.3g')} >= Std(ρ̃_orig) "
                f"{quality['std_rho_orig']:.3g}); its displacement was shortened to {shorten['scale']:.3g} of "
                f"itself (Std(ρ̃_map) {quality['std_rho_map']:.3g}, smallest Jacobian "
                f"{quality['min_jacobian']:.3g}): the field is probably unlike the training fields; {refine} (weight "
                f"refinement) or {polish} ({finish}) can help")
    if quality["worse"]:
        return (f"the network's map leaves this density less equal than it was (Std(ρ̃_map) "
                f"{quality['std_rho_map']:.3g} > Std(ρ̃_orig) {quality['std_rho_orig']:.3g}, smallest Jacobian "
                f"{quality['min_jacobian']:.3g}): the field is probably unlike the training fields; {refine} (weight "
                f"refinement) or {polish} ({finish}) can help")
    return (f"the network's map does not make this density more equal (Std(ρ̃_map) "
            f"{quality['std_rho_map']:.4g}, Std(ρ̃_orig) {quality['std_rho_orig']:.4g}: less than "
            f"{GAIN_RTOL:.1%} lower; smallest Jacobian {quality['min_jacobian']:.3g}): the field is probably unlike "
            f"the training fields, or the network is untrained; {refine} (weight refinement) or {polish} ({finish}) "
            f"can help")



def poor_map_message(report: MapReport, refine: str = "refine=True", polish: str = "polish=True") -> str | None:
    """The :func:`quality_message` of a finished density map that did not make the density more equal (``no_gain``
    of :func:`density_quality`, within :data:`GAIN_RTOL`) or had to be shortened not to leave it less equal, else
    ``None``.  A map of a grid is judged by ``report.quality``; a map of query points, which
    has no grid of its own, by the working grid's judgement in ``report.shorten``."""
    if report.quality is not None:
        if report.quality["worse"] or report.quality.get("no_gain", False) or report.shorten is not None:
            return quality_message(report.quality, refine, polish, report.shorten)
        return None
    if report.shorten is not None:
        return quality_message(report.shorten["quality"], refine, polish, report.shorten, grid_only=True)
    return None
