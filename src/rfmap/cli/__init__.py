"""The command line, ``rfmap`` (the console script is :func:`rfmap.cli.commands.entry`; ``python -m rfmap.cli``).

:mod:`~rfmap.cli.commands` holds the sub-commands (``solve``, ``metrics``, ``map``, ``train``, ``models``, ``validate``,
``reproduce``, ``cartogram``) and the parser; :mod:`~rfmap.cli.lazy_parser` adds a sub-command's arguments only when
it is used, so that the classical sub-commands do not import PyTorch.  The package exports the program's entry
points, :func:`~rfmap.cli.commands.main` and :func:`~rfmap.cli.commands.entry`, and its parser,
:func:`~rfmap.cli.commands.build_parser`.
"""
from .commands import build_parser, entry, main

__all__ = ["main", "entry", "build_parser"]
