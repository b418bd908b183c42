"""Sub-command parsers that are filled on first use, so that ``rfmap --help``, ``rfmap cartogram --help`` and the
classical sub-commands do not import what only one sub-command needs (``rfmap train`` needs PyTorch and the training
configurations, several seconds of imports).
"""
from __future__ import annotations

import argparse

__all__ = ["train_parser"]


def _deferred(parser: argparse.ArgumentParser, fill) -> argparse.ArgumentParser:
    """``parser``, whose arguments ``fill(parser)`` adds the first time it parses or formats its help or usage."""
    base = parser.__class__

    class Deferred(base):
        def _filled(self):
            self.__class__ = base
            fill(self)
            return self

        def parse_known_args(self, *args, **kwargs):
            return self._filled().parse_known_args(*args, **kwargs)

        def format_help(self):
            return self._filled().format_help()

        def format_usage(self):
            return self._filled().format_usage()

    parser.__class__ = Deferred
    return parser


def train_parser(parser: argparse.ArgumentParser) -> argparse.ArgumentParser:
    """``rfmap train``'s arguments (:func:`rfmap.training.cli.build_parser`), added to ``parser`` on first use."""
    def fill(p):
        from ..training.cli import build_parser

        build_parser(p)

    return _deferred(parser, fill)
