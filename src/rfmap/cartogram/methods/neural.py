"""The neural cartogram methods: a pretrained surrogate's map of the raster's grid (``"surrogate"``), or that map
finished by the classical flow (``"hybrid"``).  PyTorch is loaded only when such a method prepares its surrogate."""
from __future__ import annotations

import numpy as np

from .base import CartogramMethod

__all__ = ["SurrogateMethod", "HybridMethod", "HYBRID_POLISH"]

#: The hybrid's polish tolerance on Std(ρ̃_map) (``Surrogate.map(polish=...)``): far below any raster's variation,
#: so that every pass runs its flow: the cartogram's passes stop on the regions' area errors, and a polish that
#: stopped early on a nearly uniform raster would leave small regions' areas unconverged.
#: The polish runs on the raster's vertex grid (the network's map resampled to it), where the area errors are judged
#: (:doc:`Design decisions </book/design>`).
HYBRID_POLISH = 1e-9


class SurrogateMethod(CartogramMethod):
    """``"surrogate"``: the network's map on its working grid, repaired there so that it is fold-free before its
    displacement is interpolated at the polygon vertices; the surrogate is ``options.surrogate`` or the shipped
    ``options.model`` (default ``deq2d-square``), which must map 2D densities with the square's walls fixed."""

    name = "surrogate"
    classical = False
    carries_vertices = False

    def prepare(self) -> None:
        """Loads the surrogate, ``options.surrogate`` or else the shipped ``options.model`` (default
        ``deq2d-square``), and checks that it maps 2D densities with the square's walls fixed (``ValueError``
        otherwise); the hybrid method loads it the same way."""
        self.surrogate = square_surrogate(self.options.surrogate, self.options.model)

    def _map(self, density: np.ndarray, points: np.ndarray, solver_kw: dict):
        from ...finish import quiet_quality

        # the raster's Std(ρ̃) counts the sea and every region's edge; the cartogram judges a pass by its area errors
        with quiet_quality():
            return self._network_map(density)

    def _network_map(self, density: np.ndarray):
        return self.surrogate.map(density, self.surrogate.work_n(density.shape[0]), preprocess=False)


class HybridMethod(SurrogateMethod):
    """``"hybrid"``: the network's map resampled to the raster's vertex grid and finished there by the flow
    (``Surrogate.map(polish=HYBRID_POLISH)``)."""

    name = "hybrid"

    def _network_map(self, density: np.ndarray):
        return self.surrogate.map(density, density.shape[0], preprocess=False, polish=HYBRID_POLISH)


def square_surrogate(surrogate, model: str | None):
    """The surrogate of a cartogram (``surrogate``, else the shipped ``model``, default ``deq2d-square``), checked
    to map 2D densities with the square's walls fixed (``ValueError`` otherwise)."""
    if surrogate is None:
        from ...surrogate import Surrogate

        surrogate = Surrogate.pretrained(model or "deq2d-square")
    spec = surrogate.spec
    if not (spec.task.equalizes and spec.dim == 2 and spec.boundary == "square"):
        raise ValueError(f"a cartogram needs a 2D density model of the square (e.g. deq2d-square); "
                         f"{surrogate.name!r} maps {spec.dim}D {spec.kind} fields with a {spec.boundary} boundary")
    return surrogate
