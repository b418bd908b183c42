"""The cartogram chapter's tables: the methods compared on Montreal, and a series of cartograms warm against cold,
each narrow enough for the book's text column."""
from __future__ import annotations

import numpy as np

from .tables import format_value

__all__ = ["methods_table", "series_table", "judged_max_error"]


def judged_max_error(carto, min_share: float = 1e-4) -> float:
    """The largest relative area error of a cartogram over the regions holding at least ``min_share`` of the total
    value (as :class:`rfmap.cartogram.series.SeriesFrame` judges a frame)."""
    share = carto.values / carto.values.sum()
    return float(carto.area_errors[share >= min_share].max())


def methods_table(cartos: dict) -> str:
    """Markdown: one row per ``(value, method)`` of :func:`rfmap.cartogram.resize.compare_cartograms`' result, with the
    passes, the mean and largest area error and the seconds from GeoJSON to mapped polygons (six columns)."""
    lines = ["| value | method | passes | mean error | max error | time |", "|---|---|---:|---:|---:|---:|"]
    for (v, label), c in cartos.items():
        m = c.metrics()
        lines.append(f"| {v} | {label} | {c.info['iterations']} | {m.mean_error:.2g} | {m.max_error:.3g} | "
                     f"{format_value(float(c.time), 'time')} |")
    return "\n".join(lines)


def series_table(warm, cold, labels=None) -> str:
    """Markdown: one row per frame of two :class:`rfmap.cartogram.series.CartogramSeries` (warm and cold), with the
    passes, the seconds and the largest area error over the judged regions of each (seven columns), and their
    totals (the largest error over all frames)."""
    labels = list(labels) if labels is not None else [f.key for f in warm.frames]
    lines = ["| frame | warm passes | cold passes | warm time | cold time | warm error | cold error |",
             "|---|---:|---:|---:|---:|---:|---:|"]
    for lab, w, c in zip(labels, warm.frames, cold.frames):
        lines.append(f"| {lab} | {w.passes} | {c.passes} | {format_value(w.seconds, 'time')} | "
                     f"{format_value(c.seconds, 'time')} | {w.max_error:.3g} | {c.max_error:.3g} |")
    tw, tc = float(np.sum(warm.seconds)), float(np.sum(cold.seconds))
    lines.append(f"| all | {int(warm.passes.sum())} | {int(cold.passes.sum())} | {format_value(tw, 'time')} | "
                 f"{format_value(tc, 'time')} | {warm.max_errors.max():.3g} | {cold.max_errors.max():.3g} |")
    return "\n".join(lines)
