"""Plots of the studies' tables and reports: time against accuracy, displacement demand, a column of a table
against N, and the shortening curve."""
from __future__ import annotations

import numpy as np

__all__ = ["time_accuracy_figure", "displacement_demand_figure", "table_lines", "resolution_panels", "shorten_curve",
           "COLUMN_NAMES",
           "plain_log_ticks", "decade_ticks"]


#: axis names of table columns
COLUMN_NAMES = {"std_rho_map": r"Std($\tilde\rho_{map}$)", "raw_std": r"raw Std($\tilde\rho_{map}$)"}


def plain_log_ticks(axis) -> None:
    """Label a log ``axis`` (``ax.xaxis`` or ``ax.yaxis``, after plotting) in plain numbers (``0.02``, ``5``,
    ``1000``, ``1e-05`` when shorter) at 1, 2 and 5 times the powers of ten, or at up to three round values spaced
    about evenly on the log scale where the data span less than a factor of five, with no labels between them, so that
    labels never overlap."""
    from matplotlib.ticker import FixedLocator, FuncFormatter, LogLocator, NullFormatter

    axis.axes.autoscale_view()
    lo, hi = sorted(abs(v) for v in axis.get_view_interval())
    if lo > 0 and hi / lo < 5:
        axis.set_major_locator(FixedLocator(_round_log_values(lo, hi)))
    else:
        axis.set_major_locator(LogLocator(subs=(1.0, 2.0, 5.0), numticks=12))
    axis.set_major_formatter(FuncFormatter(_plain))
    axis.set_minor_formatter(NullFormatter())


def _plain(v: float, _pos=None) -> str:
    """A tick value in three significant digits, written out in full from 1 to a million (``1000``, not
    ``1e+03``)."""
    text = f"{v:.3g}"
    return f"{v:.0f}" if "e+" in text and abs(v) < 1e6 else text


def _round_log_values(lo: float, hi: float) -> list[float]:
    """Up to three round values (1, 1.5, 2, 3, 4, 5, 6 or 8 times a power of ten) inside ``[lo, hi]``, each the
    one nearest on the log scale to a quarter, half and three quarters of the interval; where fewer than two such
    values fall inside, evenly spaced round steps (``0.08, 0.09``; ``0.2, 0.22, 0.24``) as a linear axis has them."""
    e0, e1 = int(np.floor(np.log10(lo))), int(np.ceil(np.log10(hi)))
    nice = np.array(sorted(m * 10.0**e for e in range(e0, e1 + 1) for m in (1, 1.5, 2, 3, 4, 5, 6, 8)))
    nice = nice[(nice >= lo) & (nice <= hi)]
    targets = np.geomspace(lo, hi, 5)[1:-1]
    if len(nice) < 2:  # a narrow range: evenly spaced round steps (0.08, 0.09), as a linear axis labels them
        from matplotlib.ticker import MaxNLocator

        inside = [v for v in MaxNLocator(nbins=3, steps=[1, 2, 5, 10]).tick_values(lo, hi) if lo <= v <= hi]
        if len(inside) >= 2:
            return [float(f"{v:.3g}") for v in (inside[::2] if len(inside) > 3 else inside)]
        return sorted({float(f"{t:.2g}") for t in targets})
    picked = {float(nice[np.argmin(abs(np.log(nice) - np.log(t)))]) for t in targets}
    return sorted(float(f"{v:.3g}") for v in picked)


def decade_ticks(axis) -> None:
    """Label a log ``axis`` at its powers of ten only, in plain numbers (``0.1``, ``1``, ``100``), no minor labels:
    for a narrow panel over several decades, where :func:`plain_log_ticks` would crowd its labels."""
    from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter

    axis.set_major_locator(LogLocator(subs=(1.0,), numticks=12))
    axis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
    axis.set_minor_formatter(NullFormatter())


def time_accuracy_figure(rows: list[dict], *, title: str | None = None, ncols: int = 2):
    """Std(rho~_map) against wall time (rows of :func:`rfmap.paper.benchmarks.time_to_accuracy`), log-log axes: one
    panel per (dimension, N, boundary), in the order the rows give them, in a grid of ``ncols`` columns (3.6 inches
    each); one marker per field and method, its colour the method's and its shape the field's (rows without a
    ``field`` share one shape), so that a single field can be followed across methods and panels; and one legend of
    the methods (colours) and one of the fields (shapes), in an empty panel or else below the panels."""
    import matplotlib.pyplot as plt

    cases = list(dict.fromkeys((r["dim"], r["n"], r["boundary"]) for r in rows))
    methods = list(dict.fromkeys(r["method"] for r in rows))
    fields = list(dict.fromkeys(r.get("field", "") for r in rows))
    shapes = dict(zip(fields, "osD^v<>ph*P"))
    ncols = max(1, min(ncols, len(cases)))
    nrows = -(-len(cases) // ncols)
    fig, axes = plt.subplots(nrows, ncols, figsize=(3.6 * ncols, 3.3 * nrows + 0.4), layout="constrained",
                             squeeze=False)
    for ax, case in zip(axes.flat, cases):
        for r in (r for r in rows if (r["dim"], r["n"], r["boundary"]) == case):
            ax.loglog(r["time"], r["std_rho_map"], shapes[r.get("field", "")],
                      color=f"C{methods.index(r['method'])}", alpha=0.8, mfc="none")
        ax.set_title(f"{case[0]}D, N = {case[1]}, {case[2]}", fontsize="medium", pad=8)
        plain_log_ticks(ax.xaxis)
        plain_log_ticks(ax.yaxis)
        ax.set_xlabel("wall time (s)")
        ax.set_ylabel(r"Std($\tilde\rho_{\mathrm{map}}$)")
    for ax in list(axes.flat)[len(cases):]:
        ax.set_axis_off()
    # room between a panel's axis label and the title of the panel below it
    fig.get_layout_engine().set(h_pad=0.2)
    _time_accuracy_legends(fig, axes, len(cases), methods, fields if len(fields) > 1 else [], shapes)
    if title:
        fig.suptitle(title)
    return fig


def _time_accuracy_legends(fig, axes, used: int, methods: list, fields: list, shapes: dict) -> None:
    """The legend of the methods (colour) and of the fields (shape) of :func:`time_accuracy_figure`: one above the
    other, in two columns each, in the first empty panel, or else below the panels."""
    from matplotlib.lines import Line2D

    by_method = [Line2D([], [], ls="none", marker="s", color=f"C{k}", label=m) for k, m in enumerate(methods)]
    by_field = [Line2D([], [], ls="none", marker=shapes[f], color="0.3", mfc="none", label=f) for f in fields]
    if used < axes.size:  # the legends in the first empty panel
        ax = list(axes.flat)[used]
        if by_field:
            ax.add_artist(ax.legend(handles=by_field, loc="lower center", title="field", ncols=2))
        ax.legend(handles=by_method, loc="upper center" if by_field else "center", title="method", ncols=2)
    else:
        fig.legend(handles=by_method + by_field, loc="outside lower center", ncols=min(4, len(methods) + len(fields)))


def displacement_demand_figure(records: list[dict], *, title: str | None = None):
    """Left: the network map's largest displacement (reach) against the classical map's (demand), one marker per
    field, with the line reach = demand; right: the fraction of the non-uniformity each map leaves,
    Std(rho~_map) / Std(rho~_orig), against the demand.  The band marks the demand of 90 % of the training draws
    (records of :func:`rfmap.paper.generalization.displacement_demand`); the legend is below the panels and names
    the right panel's markers: o for the network map, x for the classical map."""
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D

    groups = list(dict.fromkeys(r["group"] for r in records))
    fig, (a, b) = plt.subplots(1, 2, figsize=(7.2, 3.8), layout="constrained")
    train = [r["demand"] for r in records if r["group"] == "training"]
    if train:
        p90 = float(np.quantile(train, 0.9))
        for ax in (a, b):
            ax.axvspan(0, p90, color="0.9", zorder=0, label="90 % of training draws")
    for k, g in enumerate(groups):
        rs = [r for r in records if r["group"] == g]
        d = [r["demand"] for r in rs]
        kw = dict(color=f"C{k}", alpha=0.35 if g == "training" else 0.9, ms=4 if g == "training" else 7)
        a.plot(d, [r["reach"] for r in rs], "o", label=g, **kw)
        b.plot(d, [r["left_net"] for r in rs], "o", label=f"{g}: ours", **kw)
        if g != "training":
            b.plot(d, [r["left_classical"] for r in rs], "x", color=f"C{k}", ms=6)
    top = max(max(r["demand"] for r in records), max(r["reach"] for r in records)) * 1.05
    a.plot([0, top], [0, top], "k--", lw=1, label="reach = demand")
    a.set_xlim(0, top)
    a.set_ylim(0, top)
    a.set_xlabel("demand: classical map's\nlargest displacement")
    a.set_ylabel("reach: network map's\nlargest displacement")
    # below the panels, where it covers no marker; the two marker shapes of the right panel named too
    handles, labels = a.get_legend_handles_labels()
    handles += [Line2D([], [], ls="none", marker=m, color="0.3", ms=6) for m in "ox"]
    labels += ["o: network map (ours)", "x: classical map"]
    fig.legend(handles, labels, loc="outside lower center", ncols=min(len(labels), 4), frameon=False)
    b.set_xlim(0, top)
    b.set_yscale("log")
    plain_log_ticks(b.yaxis)
    b.set_xlabel("demand: classical map's\nlargest displacement")
    b.set_ylabel(r"Std($\tilde\rho_{map}$) / Std($\tilde\rho_{orig}$)" + "\n(fraction left)")
    if title:
        fig.suptitle(title)
    return fig


def table_lines(table, column: str = "std_rho_map", ax=None, *, logx: bool = True, mark_folded: bool = False):
    """One line per ``method`` of an :class:`rfmap.paper.tables.Table` whose cases are numbers (e.g. grid sides):
    ``column`` against the case; returns the axes.

    With ``mark_folded``, a row whose raw map folded (``n_flipped`` > 0, for the ``raw_std`` column) is not
    plotted as a value, since the Std of a map with negative areas is not a spread of the density: it is marked by
    a cross at the top of the axes, in its method's colour, and the legend names the mark "folded"."""
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D
    from matplotlib.ticker import NullLocator

    if ax is None:
        _, ax = plt.subplots(figsize=(5.2, 3.4), layout="constrained")
    methods = list(dict.fromkeys(m for _, m, _ in table.rows))
    folded_any = False
    for k, method in enumerate(methods):
        color = f"C{k // 2 if len(methods) > 2 else k}"
        rows = [(float(c), v) for c, m, v in table.rows if m == method and v.get(column) is not None]
        folded = [c for c, v in rows if mark_folded and column == "raw_std" and (v.get("n_flipped") or 0) > 0]
        pts = sorted((c, v[column]) for c, v in rows if c not in folded)
        ls = "--" if "native" in method else "-"
        if pts:
            ax.plot(*zip(*pts), ls, marker="o", ms=3, lw=1.2, color=color, label=method)
        if folded:
            folded_any = True
            ax.plot(folded, [0.96] * len(folded), "x", ms=7, mew=1.6, color=color,
                    transform=ax.get_xaxis_transform(), clip_on=False)
    if logx:
        ax.set_xscale("log", base=2)
        ns = sorted({float(c) for c, _, _ in table.rows})
        ax.set_xticks(ns, [f"{n:g}" for n in ns])
        ax.xaxis.set_minor_locator(NullLocator())
    ax.set_yscale("log")
    plain_log_ticks(ax.yaxis)
    ax.set(xlabel="N", ylabel=COLUMN_NAMES.get(column, column))
    handles, labels = ax.get_legend_handles_labels()
    if folded_any:
        handles.append(Line2D([], [], ls="", marker="x", ms=7, mew=1.6, color="0.3"))
        labels.append("folded (not plotted)")
    ax.legend(handles, labels)
    return ax


def resolution_panels(table, *, title: str | None = None):
    """Two panels of a resolution table (:func:`rfmap.paper.compare.resolution_table`) against the grid side:
    the raw network map (left; a folded map is marked by a cross, not plotted, see :func:`table_lines`) and the map
    after the bijectivity repair (right), on one y axis, with one legend below both panels, where it hides no
    point; returns the figure."""
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(7.2, 3.3), layout="constrained", sharey=True)
    table_lines(table, "raw_std", axes[0], mark_folded=True)
    table_lines(table, "std_rho_map", axes[1])
    axes[0].set(title="raw network map", ylabel=COLUMN_NAMES["std_rho_map"])
    axes[1].set(title="after bijectivity repair", ylabel="")
    legend = axes[0].get_legend()  # it names the folded mark too
    handles, labels = legend.legend_handles, [t.get_text() for t in legend.get_texts()]
    for ax in axes:
        ax.get_legend().remove()
    fig.legend(handles, labels, loc="outside lower center", ncols=min(len(labels), 4), frameon=False)
    _label_lowest(axes[0].yaxis)
    if title:
        fig.suptitle(title)
    return fig


def _label_lowest(axis) -> None:
    """On a log ``axis`` labelled by :func:`plain_log_ticks` over less than a factor of five, add a labelled tick
    at the lowest round value in view (``0.07`` on an axis from 0.069) and unlabelled minor ticks at every step of
    that size, so that values below the lowest round label can be read off."""
    from matplotlib.ticker import FixedLocator, MultipleLocator

    lo, hi = sorted(axis.get_view_interval())
    if not (lo > 0 and hi / lo < 5):
        return
    step = 10.0 ** np.floor(np.log10(lo))
    first = float(f"{np.ceil(lo / step - 1e-9) * step:.6g}")
    ticks = sorted(t for t in axis.get_majorticklocs() if lo <= t <= hi)
    if ticks and first < ticks[0] and np.log10(ticks[0] / first) > 0.04:
        axis.set_major_locator(FixedLocator([first, *ticks]))
    axis.set_minor_locator(MultipleLocator(step))


def shorten_curve(report: dict, ax=None, *, title: str | None = None):
    r"""Std(rho~) of the shortened maps :math:`u_s = x + s\,(u - x)` against the scale ``s``, from the report of
    :func:`rfmap.finish.shorten.shorten_map` (``info["shorten"]`` of ``Surrogate.map``): the evaluated scales (folded ones
    marked at the top), the identity's level and the chosen scale; returns the axes."""
    import matplotlib.pyplot as plt

    if ax is None:
        _, ax = plt.subplots(figsize=(5.2, 3.4), layout="constrained")
    s, j = np.array(report["curve"], dtype=float).T
    ok = np.isfinite(j)
    ax.plot(s[ok], j[ok], "o-", ms=3, lw=1.2, color="C0", label=r"fold-free $u_s$")
    if (~ok).any():
        top = float(j[ok].max()) if ok.any() else 1.0
        ax.plot(s[~ok], np.full((~ok).sum(), top), "x", color="C3", label=r"folded $u_s$")
    ax.axhline(report["std_identity"], color="0.4", ls=":", lw=1, label="identity (no map)")
    ax.axvline(report["scale"], color="C2", ls="--", lw=1, label=f"chosen s = {report['scale']:.3g}")
    ax.set(xlabel="scale s of the displacement", ylabel=r"Std($\tilde\rho_{map}$)", title=title)
    ax.legend(fontsize=8)
    return ax
