"""The network's encoder-decoder structure drawn from its own modules, its encoded inputs and its outputs."""
from __future__ import annotations

from .figures import colorbar as add_colorbar
from .figures import frameless

__all__ = ["architecture_diagram", "encoding_figure", "displacement_grids_figure"]

#: inches per unit of the drawing (a box is 1.2 units wide) and the size of its text: readable at the book's width
UNIT_INCHES, FONT_PT = 0.56, 9


def architecture_diagram(model, ax=None):
    """Draw the encoder–decoder structure of a :class:`rfmap.nn.MultiResUNet` from its own modules.

    Walks ``model.lift``, ``model.down``, ``model.up``, ``model.dec`` and ``model.head`` and draws one box per
    stage, labelled with the channel counts read from the stage's convolutions (``in_channels`` /
    ``out_channels``), arrows for pooling and up-sampling, and dashed arrows for the skip connections.  The input
    and the lift stand above the first encoder, the head and the output above the last decoder.  Boxes of
    enhanced double convolutions with spatial attention are marked "+ attn".

    Returns
    -------
    matplotlib Axes
    """
    import matplotlib.pyplot as plt

    from ..nn.blocks import SpatialAttention

    levels = len(model.down)
    dx, dy, w, h = 1.75, 1.35, 1.5, 0.92
    top = 1.55  # the input and the lift stand above the first encoder, the head and the output above the last decoder
    if ax is None:
        width = 2 * (levels - 1) * dx + 2.1
        fig = plt.figure(figsize=(UNIT_INCHES * width, UNIT_INCHES * ((levels - 1) * dy + 2 * top + 1.0)))
        ax = fig.add_axes((0, 0, 1, 1))

    def box(x, y, text, color, height=h, width=w):
        ax.add_patch(plt.Rectangle((x - width / 2, y - height / 2), width, height, facecolor=color,
                                   edgecolor="0.25", lw=0.8, zorder=2))
        ax.text(x, y, text, ha="center", va="center", fontsize=FONT_PT, zorder=3, linespacing=1.1)

    def arrow(p, q, text="", style="-|>", ls="-", color="0.2", offset=(0.0, 0.0), **kw):
        ax.annotate("", xy=q, xytext=p, arrowprops=dict(arrowstyle=style, lw=0.9, ls=ls, color=color,
                                                        shrinkA=0, shrinkB=0), zorder=1)
        if text:
            ax.text((p[0] + q[0]) / 2 + offset[0], (p[1] + q[1]) / 2 + offset[1], text, fontsize=FONT_PT,
                    ha="center", va="center", color=color, linespacing=1.1, **kw)

    def edc_label(block, name):
        conv = block.body[0].loc
        attn = " + attn" if isinstance(block.attn, SpatialAttention) else ""
        return f"{name}\nEDC{attn}\n{conv.in_channels}→{conv.out_channels}"

    lift = model.lift
    scales = ", ".join("1" if s == 1 else f"1/{s}" for s in lift.scales)
    c_in, c_lift = lift.lift[0].in_channels, lift.lift[0].out_channels
    x0 = 0.0
    box(x0, 2 * top, f"input [x, p]\n{c_in} channels", "#e8e8e8")
    box(x0, top, f"lift, scales {scales}\n1×1: {c_in}→{c_lift} each\nmix 1×1: "
                 f"{lift.mix.in_channels}→{lift.mix.out_channels}", "#cfe3f5", height=1.0, width=2.5)
    arrow((x0, 2 * top - h / 2), (x0, top + 0.5))
    arrow((x0, top - 0.5), (x0, h / 2))
    enc_pos = []
    for i, block in enumerate(model.down):
        x, y = x0 + i * dx, -i * dy
        enc_pos.append((x, y))
        box(x, y, edc_label(block, "bottleneck" if i == levels - 1 else f"encoder {i}"),
            "#f3d9b1" if i == levels - 1 else "#d8ecd0")
        if i > 0:
            px, py = enc_pos[i - 1]
            arrow((px, py - h / 2), (x - w / 2, y), "pool 2×", offset=(-0.75, -0.1))
    prev = enc_pos[-1]
    x_dec = x0
    for j, (up, dec) in enumerate(zip(model.up, model.dec)):
        i = levels - 2 - j  # level of this decoder stage
        x_dec, y = x0 + (2 * (levels - 1) - i) * dx, -i * dy
        box(x_dec, y, edc_label(dec, f"decoder {i}"), "#d8ecd0")
        arrow((prev[0] + w / 2, prev[1]), (x_dec, y - h / 2), f"up\n{up.in_channels}→{up.out_channels}",
              offset=(0.6, -0.12))
        ex, ey = enc_pos[i]
        skip_c = model.down[i].body[0].loc.out_channels
        arrow((ex + w / 2, ey), (x_dec - w / 2, y), f"skip, {skip_c} ch", ls="--", color="tab:blue",
              offset=(0.0, 0.14))
        prev = (x_dec, y)
    head = model.head
    box(x_dec, top, f"head, 1×1 conv\n{head.in_channels}→{head.out_channels}", "#cfe3f5", width=2.2)
    box(x_dec, 2 * top, f"ψ, {head.out_channels} ch\nu = x + B⊙ψ", "#e8e8e8", width=1.8)
    arrow((x_dec, h / 2), (x_dec, top - h / 2))
    arrow((x_dec, top + h / 2), (x_dec, 2 * top - h / 2))
    ax.set_xlim(x0 - 1.3, x_dec + 1.15)
    ax.set_ylim(-(levels - 1) * dy - 0.5, 2 * top + 0.5)
    ax.set_aspect("equal")
    ax.set_axis_off()
    return ax


def encoding_figure(encodings, names, *, width: float = 7.2):
    """The channels of encoded inputs (:func:`rfmap.tasks.base.encode`), one row per input and one panel per channel,
    each with its colour bar: the coordinate channels in viridis, the field's channels in a diverging map.

    ``encodings``: tensors or arrays of shape (1, C, N, N), one per row; ``names``: the channel names of each row
    (the panels are titled "c: name").  The free panels of a shorter row say how many channels it has.  Returns
    the figure.
    """
    import matplotlib.pyplot as plt
    import numpy as np

    cols = max(len(row) for row in names)
    fig, axes = plt.subplots(len(encodings), cols, figsize=(width, 2.0 * len(encodings)), layout="constrained",
                             squeeze=False)
    for row, (enc, row_names) in enumerate(zip(encodings, names)):
        enc = np.asarray(enc)
        for c, name in enumerate(row_names):
            ax = axes[row, c]
            im = ax.imshow(enc[0, c].T, origin="lower", extent=(0, 1, 0, 1), cmap="viridis" if c < 2 else "RdBu_r")
            ax.set_title(f"{c}: {name}")
            add_colorbar(im, fig=fig, ax=ax, shrink=0.8)
        for ax in axes[row, len(row_names):]:  # a shorter row says in its free panel what it holds
            ax.set_axis_off()
            field = len(row_names) - 2
            ax.text(0.5, 0.5, f"{len(row_names)} channels:\n2 coordinates,\n{field} field channel"
                    + ("s" if field != 1 else ""), ha="center", va="center", transform=ax.transAxes)
    return fig


def displacement_grids_figure(rows: dict, sizes, *, limit: float = 0.05, width: float = 7.4):
    r"""The first component :math:`\psi_1` of a network's displacement on grids of several sizes: one row per
    way of obtaining it (``rows`` maps a row's name to ``{N: psi}``, each ``psi`` of shape (2, N, N)), one panel per
    side in ``sizes``, all on one diverging colour scale from ``-limit`` to ``limit`` with one colour bar.  Returns
    the figure."""
    import matplotlib.pyplot as plt
    import numpy as np

    fig, axes = plt.subplots(len(rows), len(sizes), figsize=(width, 2.0 * len(rows)), layout="constrained",
                             squeeze=False)
    for ax_row, (label, source) in zip(axes, rows.items()):
        for ax, n in zip(ax_row, sizes):
            im = ax.imshow(np.asarray(source[n][0]).T, origin="lower", extent=(0, 1, 0, 1), cmap="RdBu_r",
                           vmin=-limit, vmax=limit)
            ax.set_title(f"{label}, N = {n}")
            frameless(ax)
    add_colorbar(im, fig=fig, ax=axes, shrink=0.6, extend="both", label=r"$\psi_1$")
    return fig
