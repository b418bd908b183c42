"""2D maps on their meshes: grid lines, element and vertex values, and the paper's population and reconstruction
panels."""
from __future__ import annotations

import numpy as np

from ..core.wording import format_sig, power_of_ten
from .figures import ColorScale, color_scale, frameless, save_figure, style
from .figures import colorbar as add_colorbar

__all__ = ["element_rho", "plot_mesh", "repair_figure", "plot_slice_outline", "plot_density", "plot_mu", "plot_map_row",
           "plot_beltrami_row", "vertex_error_panels", "population_figure", "map_rows_figure", "beltrami_figure",
           "beltrami_case_figure", "extreme_figure", "folded_maps_figure", "query_points_figure", "random_fields_figure",
           "jitter_figure", "TEXT_WIDTH_IN", "grid_line_step", "grid_lines_drawn"]


#: width of a figure that fills the book's text column with its 9 pt text shown at 9 pt (``rfmap.viz.figures``)
TEXT_WIDTH_IN = 7.2


def element_rho(result) -> np.ndarray:
    """Per-element density :math:`\\tilde\\rho` on the mapped mesh (population / mapped measure, mean 1); the
    same as :meth:`rfmap.core.result.MapResult.rho`."""
    return result.rho()


def _grid_lines(ax, pts, n, step, **kw):
    # butt caps: a projecting cap pokes past the mesh's corners as a stray grey dot
    kw.setdefault("solid_capstyle", "butt")
    P = pts.reshape(n, n, 2)
    idx = list(range(0, n, step))
    if idx[-1] != n - 1:
        idx.append(n - 1)
    for i in idx:
        ax.plot(P[i, :, 0], P[i, :, 1], **kw)
        ax.plot(P[:, i, 0], P[:, i, 1], **kw)


def grid_line_step(n: int, max_lines: int = 40) -> int:
    """The step between the grid lines that :func:`plot_mesh` draws of an ``n``-grid (1: every line):
    ``max(1, (n - 1) // max_lines)``, which draws fewer than ``2 * max_lines`` lines per direction."""
    return max(1, (n - 1) // max_lines)


def grid_lines_drawn(n: int, max_lines: int = 40) -> str:
    """The grid lines :func:`plot_mesh` draws of an ``n``-grid, in words: ``"every grid line"``, ``"every other
    grid line"`` or ``"every 3rd grid line"``, for a figure's caption."""
    step = grid_line_step(n, max_lines)
    if step <= 2:
        return "every grid line" if step == 1 else "every other grid line"
    suffix = {1: "st", 2: "nd", 3: "rd"}.get(step % 10 if step % 100 not in (11, 12, 13) else 0, "th")
    return f"every {step}{suffix} grid line"


def plot_mesh(ax, points, elements=None, *, n: int | None = None, max_lines: int = 40, title: str | None = None,
              color="0.2", lw=0.5):
    """Draw a (mapped) 2D grid mesh: grid lines when the grid side ``n`` is given (at most ``max_lines`` per
    direction), else the triangle edges."""
    points = np.asarray(points)
    if n is not None and n * n == points.shape[0]:
        _grid_lines(ax, points, n, grid_line_step(n, max_lines), color=color, lw=lw)
    else:
        ax.triplot(points[:, 0], points[:, 1], elements, color=color, lw=lw * 0.6)
    ax.set_aspect("equal")
    frameless(ax)
    if title:
        ax.set_title(title)


def plot_slice_outline(ax, points, n: int, k: int | None = None, *, title: str | None = None, max_lines: int = 20,
                       color="0.2", lw=0.5):
    """Draw the image of the slice ``z = k / (N - 1)`` of a map of the 3D ``N``-grid, projected on the xy-plane:
    its grid lines (at most ``max_lines`` per direction) and, thicker, its outline.  ``k`` defaults to the middle.

    ``points``: mapped vertices (N^3, 3) in the grid's order (:func:`rfmap.core.mesh.grid_points`).
    """
    P = np.asarray(points).reshape(n, n, n, 3)[:, :, (n - 1) // 2 if k is None else int(k), :2]
    _grid_lines(ax, P.reshape(-1, 2), n, max(1, (n - 1) // max_lines), color=color, lw=lw)
    loop = np.concatenate([P[:, 0], P[-1, 1:], P[-2::-1, -1], P[0, -2::-1]])
    ax.plot(loop[:, 0], loop[:, 1], color="C3", lw=2 * lw + 0.5)
    ax.set_aspect("equal")
    frameless(ax)
    if title:
        ax.set_title(title)


def plot_density(ax, points, elements, values, *, title=None, colorbar=True, scale: ColorScale | None = None, **kw):
    """Per-element (length m) or per-vertex (length P) values on a 2D mesh, coloured by ``scale``
    (:class:`rfmap.viz.figures.ColorScale`; its fields ``vmin``, ``vmax``, ``cmap`` may be given as keywords).

    The triangles are drawn unsnapped (``snap=False``): snapped to the pixel grid, the row of triangles along a
    straight edge of the domain rounds to alternate pixels and leaves a saw-tooth of background along it."""
    sc = color_scale(scale, **kw)
    vmin, vmax, cmap = sc.vmin, sc.vmax, sc.cmap
    values = np.asarray(values)
    if values.shape[0] == len(elements):
        im = ax.tripcolor(points[:, 0], points[:, 1], elements, facecolors=values, vmin=vmin, vmax=vmax, cmap=cmap,
                          snap=False)
    else:
        im = ax.tripcolor(points[:, 0], points[:, 1], elements, values, shading="gouraud", vmin=vmin, vmax=vmax,
                          cmap=cmap, snap=False)
    ax.set_aspect("equal")
    frameless(ax)
    if title:
        ax.set_title(title)
    if colorbar:
        add_colorbar(im, ax=ax, fraction=0.046, pad=0.03)
    return im


def plot_mu(ax, result, *, title=r"$|\mu|$ on the mapped mesh", vmax=None):
    """:math:`|\\mu|` per triangle of a 2D map, drawn on the mapped mesh."""
    return plot_density(ax, result.mapped_points, result.elements, np.abs(result.mu()), title=title, vmin=0, vmax=vmax,
                        cmap="magma")


def plot_map_row(axes, result, *, n: int | None = None, rho_range=(0.0, 2.5), label: str = ""):
    """The five panels of the paper's 2D population figures: original mesh, mapped mesh, density on the original
    and on the mapped mesh, and :math:`|\\mu|` on the mapped mesh."""
    pop_orig = result.field.reshape(-1)
    el = result.elements
    plot_mesh(axes[0], result.ref_points, el, n=n, title=f"{label} original" if label else "original")
    plot_mesh(axes[1], result.mapped_points, el, n=n, title="mapped")
    rho0 = pop_orig[el].mean(1)
    plot_density(axes[2], result.ref_points, el, rho0 / rho0.mean(), title=r"$\tilde\rho$ original",
                 vmin=rho_range[0], vmax=rho_range[1])
    plot_density(axes[3], result.mapped_points, el, element_rho(result), title=r"$\tilde\rho$ mapped",
                 vmin=rho_range[0], vmax=rho_range[1])
    if result.dim == 2:
        plot_mu(axes[4], result)


def plot_beltrami_row(axes, exact, lbs, ours, *, n: int, label: str = "", bins: int = 40):
    """The six panels of the paper's reconstruction figures: the domain coloured by :math:`|\\mu|`, the exact
    map, the Linear Beltrami Solver's map, the surrogate's map, and histograms of
    :math:`|\\mu_{\\text{truth}} - \\mu_{\\text{pred}}|` for LBS and for the surrogate (``mu_truth`` is the exact
    coefficient at the triangle centroids, stored in ``exact.field``)."""
    mu_t = exact.field
    plot_density(axes[0], exact.ref_points, exact.elements, np.abs(mu_t), title=f"{label} $|\\mu|$", cmap="magma",
                 vmin=0)
    plot_mesh(axes[1], exact.mapped_points, n=n, title="exact map")
    plot_mesh(axes[2], lbs.mapped_points, n=n, title="LBS")
    plot_mesh(axes[3], ours.mapped_points, n=n, title="surrogate")
    errs = [np.abs(mu_t - lbs.mu()), np.abs(mu_t - ours.mu())]
    hi = max(float(e.max()) for e in errs) or 1.0
    for ax, e, name in zip(axes[4:6], errs, ["LBS", "surrogate"]):
        ax.hist(e, bins=bins, range=(0, hi), color="tab:blue" if name == "LBS" else "tab:orange")
        ax.set_title(f"$|\\mu_{{truth}}-\\mu_{{pred}}|$ {name}")
        ax.set_yscale("log")


def vertex_error_panels(results: dict, exact, *, n: int, title: str = ""):
    r"""One panel per 2D map of ``results`` (``{name: MapResult}`` on the ``n``-grid): the vertex error
    :math:`|u(x) - u_{\text{exact}}(x)|` as an image over the unit square, on a shared colour scale, with its mean
    in the panel title (all titles in one notation).

    Parameters
    ----------
    results : dict of str to MapResult
        Maps of the same grid of side N (``ref_points`` of shape (N², 2)).
    exact : MapResult
        The exact map on the same grid.

    Returns
    -------
    matplotlib Figure
    """
    import matplotlib.pyplot as plt

    errs = {}
    for name, r in results.items():
        if r.ref_points.shape != (n * n, 2) or exact.mapped_points.shape != (n * n, 2):
            raise ValueError(f"vertex_error_panels needs 2D maps of the {n}-grid, got {r.ref_points.shape}")
        errs[name] = np.linalg.norm(r.mapped_points - exact.mapped_points, axis=1).reshape(n, n)
    hi = max(float(e.max()) for e in errs.values()) or 1.0
    means = {name: format_sig(float(e.mean()), 3) for name, e in errs.items()}
    if any("×" in t for t in means.values()):  # the titles in one notation
        means = {name: power_of_ten(float(e.mean()), 3) for name, e in errs.items()}
    fig, axes = plt.subplots(1, len(errs), figsize=(3.3 * len(errs), 3.0), squeeze=False)
    for ax, (name, e) in zip(axes[0], errs.items()):
        im = ax.imshow(e.T, origin="lower", extent=(0, 1, 0, 1), vmin=0, vmax=hi, cmap="magma")
        ax.set_title(f"{title} {name}: mean {means[name]}".strip())
        ax.set_aspect("equal")
        ax.set_xticks([0, 0.5, 1], labels=["0", "0.5", "1"])
        ax.set_yticks([0, 0.5, 1], labels=["0", "0.5", "1"])
        # the panels share the unit square: the y labels of the first only, so no label meets its neighbour's
        ax.tick_params(labelleft=ax is axes[0][0])
    add_colorbar(im, fig=fig, ax=axes[0].tolist(), shrink=0.85, label="vertex error")
    return fig


def _frameless(axes) -> None:
    for ax in np.ravel(axes):
        for spine in ax.spines.values():
            spine.set_visible(False)


def _grid_side(result) -> int | None:
    n = int(round(np.sqrt(len(result.ref_points))))
    return n if n * n == len(result.ref_points) else None


def map_rows_figure(results: dict, *, rho_range=(0.0, 2.5), width: float = TEXT_WIDTH_IN, max_lines: int = 20,
                    mapped_range=None):
    r"""One row per 2D map of ``results`` (``{row label: MapResult}``): the mapped mesh (at most ``max_lines``
    grid lines per direction), :math:`\tilde\rho` on the
    original and on the mapped mesh, and :math:`|\mu|` on the mapped mesh (the paper's Figs. 7-9 without their
    panel of the original grid).  The two density panels share one colour bar (``rho_range``), or, with
    ``mapped_range`` (say ``(0.8, 1.2)``), the mapped density gets a narrow scale and a colour bar of its own, so
    that what is left of the input's variation shows; the :math:`|\mu|` panels have another (0 to the largest
    :math:`|\mu|`, at most 1), so the rows compare at a glance; the figure is ``width`` inches wide, readable in
    the book's text column.

    Returns
    -------
    matplotlib Figure
    """
    import matplotlib.pyplot as plt

    k = len(results)
    fig, axes = plt.subplots(k, 4, figsize=(width, 1.62 * k + 0.75), layout="constrained", squeeze=False)
    mus = {label: np.abs(r.mu()) for label, r in results.items()}
    mu_top = max(float(m.max()) for m in mus.values())
    mu_hi = min(1.0, mu_top) or 1.0
    mapped = rho_range if mapped_range is None else mapped_range
    rho_top, low, high = 0.0, np.inf, -np.inf
    for row, (label, r) in zip(axes, results.items()):
        el = r.elements
        rho0 = np.asarray(r.field).reshape(-1)[el].mean(1)
        rho0, rho1 = rho0 / rho0.mean(), element_rho(r)
        rho_top = max(rho_top, float(rho0.max()), float(rho1.max()))
        low, high = min(low, float(rho1.min())), max(high, float(rho1.max()))
        plot_mesh(row[0], r.mapped_points, el, n=_grid_side(r), max_lines=max_lines)
        row[0].set_ylabel(label)
        im_rho = plot_density(row[1], r.ref_points, el, rho0, vmin=rho_range[0], vmax=rho_range[1], colorbar=False)
        im_map = plot_density(row[2], r.mapped_points, el, rho1, vmin=mapped[0], vmax=mapped[1], colorbar=False)
        im_mu = plot_density(row[3], r.mapped_points, el, mus[label], vmin=0, vmax=mu_hi, cmap="magma",
                             colorbar=False)
    _frameless(axes)
    for ax, title in zip(axes[0], ["mapped mesh", r"$\tilde\rho$ original", r"$\tilde\rho$ mapped",
                                   r"$|\mu|$ mapped"]):
        ax.set_title(title)
    if mapped_range is None:
        add_colorbar(im_rho, fig=fig, ax=axes[:, 1:3].ravel().tolist(), location="bottom", shrink=0.8, aspect=30,
                     label=r"$\tilde\rho$ (mean 1)", extend="max" if rho_top > rho_range[1] else "neither")
    else:
        ends = {(True, True): "both", (True, False): "min", (False, True): "max", (False, False): "neither"}
        add_colorbar(im_rho, fig=fig, ax=axes[:, 1].tolist(), location="bottom", shrink=0.95, aspect=12,
                     label=r"$\tilde\rho$ original", extend="max" if rho_top > rho_range[1] else "neither")
        add_colorbar(im_map, fig=fig, ax=axes[:, 2].tolist(), location="bottom", shrink=0.95, aspect=12,
                     label=r"$\tilde\rho$ mapped", extend=ends[low < mapped[0], high > mapped[1]])
    add_colorbar(im_mu, fig=fig, ax=axes[:, 3].tolist(), location="bottom", shrink=0.95, aspect=12,
                 label=r"$|\mu|$", extend="max" if mu_top > mu_hi else "neither")
    return fig


def population_figure(maps: dict, fields, label: str, *, method: str = "ours+refine"):
    """The paper's 2D population figure: one row of :func:`map_rows_figure` per field of the maps of
    :func:`rfmap.paper.reproduce.population_table` (the grid is read from the maps), saved under the paper's
    ``label``; returns the figure."""
    with style():
        fig = map_rows_figure({f: maps[f][method] for f in fields})
        save_figure(fig, label)
    return fig


def beltrami_figure(rows: dict, *, width: float = TEXT_WIDTH_IN, bins: int = 40, max_lines: int = 20):
    r"""The paper's reconstruction figures (Figs. 5 and 6), one row per test: the domain coloured by the exact
    :math:`|\mu|` (one colour bar for all rows), the exact map, the map of the paper's method (at most
    ``max_lines`` grid lines per direction), its vertex error :math:`|\Delta d|` (the distance of each mapped vertex
    to the exact map's, the paper's metric; one colour bar for all rows, in units of a power of ten), and the
    histograms of :math:`|\mu_{\text{exact}} - \mu|` over the triangles for the Linear Beltrami Solver and the
    paper's method (triangles on a log axis).

    Parameters
    ----------
    rows : dict
        ``{row label: (exact, lbs, ours)}`` of :class:`~rfmap.core.result.MapResult` on one 2D grid per row; ``exact.field``
        holds the exact coefficient at the triangle centroids (:func:`rfmap.paper.reproduce.exact_beltrami_result`).

    Returns
    -------
    matplotlib Figure, ``width`` inches wide
    """
    import matplotlib.pyplot as plt
    from matplotlib.ticker import MaxNLocator, NullFormatter

    k = len(rows)
    fig, axes = plt.subplots(k, 5, figsize=(width, 1.55 * k + 1.2), layout="constrained", squeeze=False,
                             gridspec_kw={"width_ratios": [1, 1, 1, 1, 1.3]})
    mu_hi = max(float(np.abs(e.field).max()) for e, _, _ in rows.values()) or 1.0
    dd = {label: np.linalg.norm(np.asarray(ours.mapped_points) - np.asarray(exact.mapped_points), axis=1)
          for label, (exact, _, ours) in rows.items()}
    dd_hi = max(float(v.max()) for v in dd.values()) or 1.0
    power = int(np.floor(np.log10(dd_hi)))
    for ax, (label, (exact, lbs, ours)) in zip(axes, rows.items()):
        mu_t, n = exact.field, _grid_side(exact)
        im = plot_density(ax[0], exact.ref_points, exact.elements, np.abs(mu_t), vmin=0, vmax=mu_hi, cmap="magma",
                          colorbar=False)
        ax[0].set_ylabel(label)
        for a, r in zip(ax[1:3], (exact, ours)):
            plot_mesh(a, r.mapped_points, r.elements, n=n, max_lines=max_lines)
        im_dd = plot_density(ax[3], exact.ref_points, exact.elements, dd[label] / 10.0 ** power, vmin=0,
                             vmax=dd_hi / 10.0 ** power, cmap="viridis", colorbar=False)
        errs = {"LBS": np.abs(mu_t - lbs.mu()), "paper's method": np.abs(mu_t - ours.mu())}
        hi = max(float(e.max()) for e in errs.values()) or 1.0
        for (name, e), color in zip(errs.items(), ("tab:blue", "tab:orange")):
            ax[4].hist(e, bins=bins, range=(0, hi), histtype="step", lw=1.3, color=color, label=name)
        ax[4].set_yscale("log")
        ax[4].yaxis.set_minor_formatter(NullFormatter())
        ax[4].xaxis.set_major_locator(MaxNLocator(2))
        ax[4].set_ylabel("triangles")
    axes[-1, 4].set_xlabel(r"$|\mu_{exact}-\mu|$")
    _frameless(axes[:, :4])
    for a, title in zip(axes[0], [r"exact $|\mu|$", "exact map", "paper's\nmethod", r"its $|\Delta d|$",
                                  "error in $\\mu$"]):
        a.set_title(title)
    add_colorbar(im, fig=fig, ax=axes[:, 0].tolist(), location="bottom", shrink=0.95, aspect=12, label=r"$|\mu|$")
    add_colorbar(im_dd, fig=fig, ax=axes[:, 3].tolist(), location="bottom", shrink=0.95, aspect=12,
                 label=rf"$|\Delta d|$ ($\times 10^{{{power}}}$)")
    handles, labels = axes[0, 4].get_legend_handles_labels()
    # under the last histogram, level with the colour bars of the other columns, not below everything: left out
    # of the layout, so that the colour bars stay just under the panels
    legend = axes[-1, 4].legend(handles, labels, loc="upper center", bbox_to_anchor=(0.5, -0.38), ncols=1)
    legend.set_in_layout(False)
    return fig


def beltrami_case_figure(label: str, exact, lbs, ours, *, width: float = TEXT_WIDTH_IN, bins: int = 40,
                         max_lines: int = 20):
    r"""One reconstruction test of :func:`beltrami_figure` drawn large, for a single case a chapter discusses: the
    domain coloured by the exact :math:`|\mu|` (with its colour bar), the exact map and the Linear Beltrami
    Solver's map in the first row; the surrogate's map and the histograms of :math:`|\mu_{\text{exact}} - \mu|`
    over the triangles for both solvers (log counts, axes labelled) in the second.  ``label`` names the case in the
    first panel's title; the arguments are those of one row of :func:`beltrami_figure`.  Returns the figure,
    ``width`` inches wide."""
    import matplotlib.pyplot as plt
    from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter

    fig = plt.figure(figsize=(width, 0.68 * width), layout="constrained")
    grid = fig.add_gridspec(2, 3)
    maps = [fig.add_subplot(grid[0, i]) for i in range(3)] + [fig.add_subplot(grid[1, 0])]
    hist = fig.add_subplot(grid[1, 1:])
    mu_t, n = exact.field, _grid_side(exact)
    plot_density(maps[0], exact.ref_points, exact.elements, np.abs(mu_t), vmin=0, cmap="magma",
                 title=f"{label}: $|\\mu|$")
    for a, r, title in zip(maps[1:], (exact, lbs, ours), ("exact map", "LBS", "surrogate")):
        plot_mesh(a, r.mapped_points, r.elements, n=n, max_lines=max_lines, title=title)
    errs = {"LBS": np.abs(mu_t - lbs.mu()), "surrogate": np.abs(mu_t - ours.mu())}
    hi = max(float(e.max()) for e in errs.values()) or 1.0
    for (name, e), color in zip(errs.items(), ("tab:blue", "tab:orange")):
        hist.hist(e, bins=bins, range=(0, hi), histtype="step", lw=1.5, color=color, label=name)
    hist.set_yscale("log")  # counts labelled at 1, 2, 5 times the powers of ten, as plain numbers
    hist.yaxis.set_major_locator(LogLocator(subs=(1.0, 2.0, 5.0)))
    hist.yaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:,.0f}"))
    hist.yaxis.set_minor_formatter(NullFormatter())
    hist.set_xlabel(r"$|\mu_{exact} - \mu|$ per triangle")
    hist.set_ylabel("triangles")
    hist.legend(title="error of")
    return fig


def extreme_figure(original, maps: dict, *, width: float = TEXT_WIDTH_IN, max_lines: int = 20):
    r"""The paper's Fig. 10: (a) the original domain, coloured by the density divided by its mean
    (:math:`\tilde\rho` before the map; the paper's (a) shows the domain alone), then each map of ``maps``
    (``{label: MapResult}``, two of them: (b), (c)), with its folded triangles filled in red, and below, per map,
    histograms of :math:`\tilde\rho` on the mapped mesh (d, e) and of :math:`|\mu|` (f, g) on shared axes.  The
    histograms cover the triangles (the :math:`\tilde\rho` axis ends at the 99th percentile of either map, at
    least 3, and the last bin holds every larger value; folded triangles, whose :math:`\tilde\rho` is negative,
    fall outside it; the :math:`|\mu|` axis reaches 1 or beyond where a folded
    triangle has :math:`|\mu| > 1`) and count on a logarithmic scale, so that a thin tail stays visible.

    Parameters
    ----------
    original : MapResult
        A map of the density (its ``field``, reference grid and elements are drawn).
    maps : dict of str to MapResult

    Returns
    -------
    matplotlib Figure, ``width`` inches wide
    """
    import matplotlib.pyplot as plt

    fig = plt.figure(figsize=(width, 5.2), layout="constrained")
    top, bottom = fig.subfigures(2, 1, height_ratios=[1.25, 1])
    ax = top.subplots(1, 1 + len(maps))
    el = original.elements
    rho0 = np.asarray(original.field).reshape(-1)[el].mean(1)
    im = plot_density(ax[0], original.ref_points, el, rho0 / rho0.mean(), title=r"(a) $\tilde\rho$ original",
                      colorbar=False)
    add_colorbar(im, fig=top, ax=ax[0], location="bottom", shrink=0.9, label=r"$\tilde\rho$ (mean 1)")
    letters = iter("bcdefg")
    for a, (label, r) in zip(ax[1:], maps.items()):
        title = f"({next(letters)}) {label} map"
        p = np.asarray(r.mapped_points)
        folded = _folded(p, el)
        plot_mesh(a, p, el, n=_grid_side(r), max_lines=max_lines,
                  title=title + (f", {len(folded)} folded (red)" if len(folded) else ""))
        for t in folded:
            a.fill(*p[el[t]].T, color="red", zorder=5)
    _frameless(ax)
    hax = bottom.subplots(1, 2 * len(maps))
    values = {"rho": {k: element_rho(r) for k, r in maps.items()}, "mu": {k: np.abs(r.mu()) for k, r in maps.items()}}
    # the rho axis ends at the 99th percentile of either map (the rarer, larger values fall in the last bin)
    top_rho = max(3.0, float(np.ceil(max(np.percentile(v, 99) for v in values["rho"].values()))))
    values["rho"] = {k: np.clip(v, None, top_rho) for k, v in values["rho"].items()}
    top_mu = max(1.0, float(max(v.max() for v in values["mu"].values())))
    hists = [(r"$\tilde\rho$", values["rho"], (0, top_rho), "tab:green"),
             (r"$|\mu|$", values["mu"], (0, top_mu), "tab:purple")]
    for j, (name, vals, rng, color) in enumerate(hists):
        for i, label in enumerate(maps):
            a = hax[j * len(maps) + i]
            a.hist(vals[label], bins=50, range=rng, color=color)
            a.set_yscale("log")
            a.set_title(f"({next(letters)}) {name}, {label}")
            if j == 0:
                a.set_xlabel(f"last bin: ≥ {top_rho - (rng[1] - rng[0]) / 50:.3g}")
            a.set_xlim(*rng)
        pair = hax[j * len(maps):(j + 1) * len(maps)]
        top = max(a.get_ylim()[1] for a in pair)  # one count scale per quantity
        for a in pair:
            a.set_ylim(0.8, top)
    bottom.supylabel("triangles (log scale)")
    return fig


def _folded(points: np.ndarray, elements: np.ndarray) -> np.ndarray:
    """Indices of the triangles whose mapped orientation is reversed or degenerate (signed area <= 0)."""
    a, b, c = (points[elements[:, k]] for k in range(3))
    area = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
    return np.flatnonzero(area <= 0)


def repair_figure(before, after, elements, *, n: int | None = None, titles=("folded map", "repaired map"),
                  width: float = TEXT_WIDTH_IN, zoom: float | None = 3.0):
    """Two 2D maps of one mesh side by side, a folded one and its repair, each with its folded triangles filled in
    red and counted in its title (appendix A's example).  ``before``, ``after``: mapped points, shape (P, 2);
    ``n``: the grid side N of a grid mesh (:math:`P = N^2`), whose grid lines are then drawn instead of its triangles.

    ``zoom``: a second row draws both maps around the folds of ``before`` (a square ``zoom`` times as wide as
    their bounding box, marked on the first row), where a few folded triangles are large enough to see; ``None``
    draws the first row only, as does a ``before`` without folds."""
    import matplotlib.pyplot as plt

    elements = np.asarray(elements)
    before, after = np.asarray(before), np.asarray(after)
    box = _fold_box(before, elements, zoom) if zoom else None
    rows = 1 if box is None else 2
    fig, axes = plt.subplots(rows, 2, figsize=(width, rows * width / 2), layout="constrained", squeeze=False)
    for col, (pts, title) in enumerate(zip((before, after), titles)):
        folded = _folded(pts, elements)
        for row in range(rows):
            ax = axes[row, col]
            head = f"{title}: {len(folded)} folded (red)" if row == 0 else f"{title}, around the folds"
            plot_mesh(ax, pts, elements, n=None if row else n, title=head)
            for t in folded:  # translucent in the close-up, where the folded triangles' edges can be seen
                ax.fill(*pts[elements[t]].T, color="red", alpha=0.5 if row else 1.0, zorder=5)
            if row:
                ax.set_xlim(box[0], box[2])
                ax.set_ylim(box[1], box[3])
        if box is not None:
            axes[0, col].add_patch(plt.Rectangle(box[:2], box[2] - box[0], box[3] - box[1], fill=False, lw=1.2,
                                                 ec="tab:blue", zorder=6))
    _frameless(axes)
    return fig


def _fold_box(points: np.ndarray, elements: np.ndarray, factor: float):
    """A square around the folded triangles of ``points`` (xmin, ymin, xmax, ymax), ``factor`` times as wide as
    their bounding box; ``None`` when nothing is folded."""
    folded = _folded(points, elements)
    if not len(folded):
        return None
    corners = points[elements[folded]].reshape(-1, 2)
    lo, hi = corners.min(0), corners.max(0)
    mid, half = (lo + hi) / 2, factor * max(float((hi - lo).max()), 1e-12) / 2
    return np.array([mid[0] - half, mid[1] - half, mid[0] + half, mid[1] + half])


def folded_maps_figure(maps: dict, *, ncols: int = 2, width: float = TEXT_WIDTH_IN, max_lines: int = 20):
    """2D maps of one grid side by side, ``ncols`` a row (``{title: MapResult}``), each with its folded triangles
    filled in red and counted under its title; at most ``max_lines`` grid lines per direction.  Returns the figure."""
    import matplotlib.pyplot as plt

    rows = -(-len(maps) // ncols)
    fig, axes = plt.subplots(rows, ncols, figsize=(width, (width / ncols + 0.45) * rows), layout="constrained",
                             squeeze=False)
    for ax, (title, r) in zip(axes.ravel(), maps.items()):
        p, el = np.asarray(r.mapped_points), np.asarray(r.elements)
        folded = _folded(p, el)
        count = f"{len(folded)} folded (red)" if len(folded) else "none folded"
        plot_mesh(ax, p, el, n=_grid_side(r), max_lines=max_lines, title=f"{title}\n{count}")
        for t in folded:
            ax.fill(*p[el[t]].T, color="red", zorder=5)
    for ax in axes.ravel()[len(maps):]:
        ax.set_axis_off()
    return fig


def query_points_figure(cloud, grid, *, width: float = TEXT_WIDTH_IN, bins: int = 50):
    r"""A map evaluated at scattered points: the points' Delaunay mesh (``cloud.ref_points`` and
    ``cloud.elements``), its image under the map, and the histograms of :math:`\tilde\rho` on the mapped cloud and
    on the mapped grid of ``grid`` (a map of the same density on a grid), as densities, over the central 98 % of
    their values (the rest counted in the end bins).  Returns the figure."""
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(width, 0.375 * width), layout="constrained", width_ratios=[1, 1, 1.3])
    for ax, pts, title in ((axes[0], cloud.ref_points, "query cloud"), (axes[1], cloud.mapped_points, "mapped cloud")):
        ax.triplot(pts[:, 0], pts[:, 1], cloud.elements, lw=0.2, color="0.3")
        ax.set_aspect("equal")
        ax.set_title(title)
        frameless(ax)
    n = _grid_side(grid)
    rhos = {"cloud": element_rho(cloud), f"grid N = {n}" if n else "grid": element_rho(grid)}
    # the bins span the central 98 % of both samples, so that a few extreme triangles do not squeeze the rest
    lo, hi = np.percentile(np.concatenate(list(rhos.values())), [1, 99])
    for label, rho in rhos.items():
        axes[2].hist(np.clip(rho, lo, hi), bins=np.linspace(lo, hi, bins + 1), alpha=0.6, label=label, density=True)
    axes[2].set(title=r"$\tilde\rho$ on the mapped mesh", xlabel=r"$\tilde\rho$ (1st-99th percentile; the rest"
                "\nin the end bins)", ylabel="fraction of triangles\nper unit of " + r"$\tilde\rho$")
    axes[2].legend()
    return fig


def random_fields_figure(mesh, densities: dict, mu_panels: dict, maps: dict, *, n: int, width: float = TEXT_WIDTH_IN,
                         max_lines: int = 16, density_label: str = "density (unit mass)"):
    r"""Random training fields on one grid mesh, four panels a row: the densities (a title and the values at the
    mesh's vertices per panel, four a row, each colour bar labelled ``density_label``), then a row of Beltrami
    fields, :math:`|\mu|` per vertex (``mu_panels``, colour bars labelled :math:`|\mu|`) followed by mapped grids
    (``maps``: title to mapped points of the ``n``-grid, drawn with at most ``max_lines`` grid lines per direction
    so that a fine grid stays readable).  Returns the figure."""
    import matplotlib.pyplot as plt

    dens = list(densities.items())
    rows = -(-len(dens) // 4) + 1
    fig, axes = plt.subplots(rows, 4, figsize=(width, 1.5 * rows), layout="constrained", squeeze=False)
    for ax, (title, values) in zip(axes[:-1].ravel(), dens):
        im = plot_density(ax, mesh.points, mesh.elements, values, title=title, colorbar=False)
        add_colorbar(im, ax=ax, fraction=0.046, pad=0.03, label=density_label)
    last = list(axes[-1])
    for title, values in mu_panels.items():
        ax = last.pop(0)
        im = plot_density(ax, mesh.points, mesh.elements, values, cmap="magma", vmin=0, title=title, colorbar=False)
        add_colorbar(im, ax=ax, fraction=0.046, pad=0.03, label=r"$|\mu|$")
    for title, points in maps.items():
        plot_mesh(last.pop(0), points, n=n, max_lines=max_lines, title=title)
    for ax in last + list(axes[:-1].ravel()[len(dens):]):
        ax.set_axis_off()
    return fig


def jitter_figure(mesh, jittered, h: float, window=(0.45, 0.75, 0.1, 0.4), *, width: float = TEXT_WIDTH_IN):
    """Sobol-jittered sampling of a grid mesh: the larger of the two coordinate offsets of every vertex, in grid
    spacings ``h`` (left; the quantity the jitter caps), and a zoom
    on ``window`` = (x0, x1, y0, y1) with the regular mesh in wide light grey lines under the jittered one in thin
    red lines (right).
    Returns the figure."""
    import matplotlib.pyplot as plt

    jittered = np.asarray(jittered)
    offset = np.abs(jittered - mesh.points).max(axis=1) / h
    fig, axes = plt.subplots(1, 2, figsize=(width, width / 2), layout="constrained")
    plot_density(axes[0], mesh.points, mesh.elements, offset, cmap="magma", vmin=0,
                 title="largest offset per coordinate,\nin grid spacings $h$")
    # the regular mesh wide and light under the jittered one thin and red, so that both stay visible
    axes[1].triplot(mesh.points[:, 0], mesh.points[:, 1], mesh.elements, color="0.7", lw=2.2)
    axes[1].triplot(jittered[:, 0], jittered[:, 1], mesh.elements, color="tab:red", lw=0.7)
    axes[1].set_xlim(window[:2])
    axes[1].set_ylim(window[2:])
    axes[1].set_aspect("equal")
    axes[1].set_title("zoom: regular (wide grey),\njittered (thin red)")
    return fig
