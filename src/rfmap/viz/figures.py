"""The book's figures: one matplotlib style, and where figures are saved under their paper labels."""
from __future__ import annotations

import os
from contextlib import contextmanager
from pathlib import Path

__all__ = ["STYLE", "style", "repository_root", "figures_dir", "save_figure"]


STYLE = {
    "figure.dpi": 110,
    "savefig.dpi": 140,
    "savefig.bbox": "tight",
    "font.size": 9,
    "axes.titlesize": 9,
    "axes.spines.top": False,
    "axes.spines.right": False,
    "image.cmap": "viridis",
}


@contextmanager
def style():
    """Context manager applying the book's matplotlib style."""
    import matplotlib.pyplot as plt

    with plt.rc_context(STYLE):
        yield


def _is_book_root(path: Path) -> bool:
    return (path / "_config.yml").is_file() and (path / "book").is_dir()


def repository_root(start: str | os.PathLike | None = None) -> Path | None:
    """The source checkout that holds the book (the directory with ``_config.yml`` and ``book/``), or ``None``.

    With ``start``, the nearest such directory at or above ``start``.  Without it, the checkout this module was
    imported from (an editable install), else the nearest one at or above the working directory (a regular install
    used inside a checkout, e.g. a notebook opened from ``notebooks/``).  The answer never depends on *which*
    directory of the checkout the caller runs in.
    """
    if start is None:
        here = Path(__file__).resolve().parents[3]
        if _is_book_root(here):
            return here
        start = Path.cwd()
    start = Path(start).resolve()
    return next((p for p in (start, *start.parents) if _is_book_root(p)), None)


def figures_dir() -> Path:
    """Where figures go: ``$RFMAP_FIGURES``, else ``book/figures`` of the checkout found by :func:`repository_root`
    (the place the book build writes to, from the repository root, from ``notebooks/`` or from anywhere else),
    else ``./figures`` outside a checkout."""
    env = os.environ.get("RFMAP_FIGURES")
    if env:
        p = Path(env)
    else:
        root = repository_root()
        p = root / "book" / "figures" if root is not None else Path.cwd() / "figures"
    p.mkdir(parents=True, exist_ok=True)
    return p


def save_figure(fig, label: str) -> Path:
    """Save ``fig`` as ``<figures_dir>/<label>.png`` where ``label`` is the paper's label (``fig:x_y`` → ``fig-x-y``)."""
    name = label.replace(":", "-").replace("_", "-")
    path = figures_dir() / f"{name}.png"
    fig.savefig(path)
    return path
