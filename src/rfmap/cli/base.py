"""What the ``rfmap`` sub-commands share: the one-line user error and the spelling of a solver's name."""
from __future__ import annotations

__all__ = ["CLIError", "solver_name"]


class CLIError(Exception):
    """A user-facing error: printed as one line (exit status 2)."""


def solver_name(text: str) -> str:
    """A method's name, with another name of a solver (:data:`rfmap.solvers.ALIASES`: ``dem``) spelled as the one."""
    from ..solvers import ALIASES

    return ALIASES.get(text, text)
