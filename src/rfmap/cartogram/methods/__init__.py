"""The methods of a cartogram pass, one strategy a file, looked up by name in :data:`METHODS`: each turns the
density raster of a pass into a map of the unit square (:class:`~rfmap.cartogram.methods.base.CartogramMethod`).
Nothing here imports PyTorch; the neural methods load it when they prepare their surrogate."""
from __future__ import annotations

from .base import MAX_N, CartogramMethod
from .diffusion import DiffusionMethod
from .flow import FLOW_BLUR, FLOW_MAX_N, FlowMethod
from .neural import HYBRID_POLISH, HybridMethod, SurrogateMethod

__all__ = ["METHODS", "ALIASES", "get_method", "CartogramMethod", "MAX_N", "FLOW_MAX_N", "FLOW_BLUR",
           "HYBRID_POLISH"]

#: The cartogram methods by name, in the order the command line lists them
METHODS: dict[str, type[CartogramMethod]] = {m.name: m for m in (DiffusionMethod, FlowMethod, SurrogateMethod,
                                                                   HybridMethod)}
#: Other names of a method (as the solvers accept them)
ALIASES = {"dem": "diffusion"}


def get_method(name: str) -> type[CartogramMethod]:
    """The method class of ``name`` (or of an alias); ``ValueError`` naming the known methods otherwise."""
    key = ALIASES.get(name, name) if isinstance(name, str) else name
    if key not in METHODS:
        raise ValueError(f"unknown cartogram method {name!r}; choose one of {', '.join(METHODS)}")
    return METHODS[key]
