"""Classical reference solvers.

* :func:`solve_lbs` -- Linear Beltrami Solver (Lui et al. 2013): the quasi-conformal map of the unit square with a
  prescribed Beltrami coefficient.
* :func:`solve_dem` -- diffusion density-equalizing map (Gastner & Newman 2004) of the unit square or cube.

Both return a :class:`rfmap.result.MapResult`; :data:`SOLVERS` / :func:`get_solver` look them up by name.
"""
from __future__ import annotations

from typing import Callable

from ..result import MapResult
from .diffusion import solve_dem
from .lbs import solve_lbs

__all__ = ["SOLVERS", "get_solver", "solve_lbs", "solve_dem"]

#: Registry of the classical solvers by name.
SOLVERS: dict[str, Callable[..., MapResult]] = {"lbs": solve_lbs, "dem": solve_dem}


def get_solver(name: str) -> Callable[..., MapResult]:
    """Look up a solver by name (``"lbs"`` or ``"dem"``); ``ValueError`` naming the known solvers otherwise."""
    if not isinstance(name, str) or name not in SOLVERS:
        raise ValueError(f"unknown solver {name!r}; known solvers: {', '.join(sorted(SOLVERS))}")
    return SOLVERS[name]
