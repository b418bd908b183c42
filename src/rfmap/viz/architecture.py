"""The network's encoder-decoder structure drawn from its own modules."""
from __future__ import annotations

__all__ = ["architecture_diagram"]


def architecture_diagram(model, ax=None):
    """Draw the encoder–decoder structure of a :class:`rfmap.nn.MultiResUNet` from its own modules.

    Walks ``model.lift``, ``model.down``, ``model.up``, ``model.dec`` and ``model.head`` and draws one box per
    stage, labelled with the channel counts read from the stage's convolutions (``in_channels`` /
    ``out_channels``), arrows for pooling and up-sampling, and dashed arrows for the skip connections.  Boxes of
    enhanced double convolutions with spatial attention are marked "+ attn".

    Returns
    -------
    matplotlib Axes
    """
    import matplotlib.pyplot as plt

    from ..nn.blocks import SpatialAttention

    levels = len(model.down)
    dx, dy, w, h = 1.45, 1.25, 1.2, 0.72
    if ax is None:
        width = 3.45 + 2 * (levels - 1) * dx + 3.1 + w
        _, ax = plt.subplots(figsize=(0.85 * width, 0.95 * ((levels - 1) * dy + 1.05)))

    def box(x, y, text, color, height=h, width=w):
        ax.add_patch(plt.Rectangle((x - width / 2, y - height / 2), width, height, facecolor=color,
                                   edgecolor="0.25", lw=0.8, zorder=2))
        ax.text(x, y, text, ha="center", va="center", fontsize=7, zorder=3)

    def arrow(p, q, text="", style="-|>", ls="-", color="0.2", offset=(0.0, 0.0), **kw):
        ax.annotate("", xy=q, xytext=p, arrowprops=dict(arrowstyle=style, lw=0.9, ls=ls, color=color,
                                                        shrinkA=0, shrinkB=0), zorder=1)
        if text:
            ax.text((p[0] + q[0]) / 2 + offset[0], (p[1] + q[1]) / 2 + offset[1], text, fontsize=6.5,
                    ha="center", va="center", color=color, **kw)

    def edc_label(block, name):
        conv = block.body[0].loc
        attn = " + attn" if isinstance(block.attn, SpatialAttention) else ""
        return f"{name}\nEDC{attn}\n{conv.in_channels}→{conv.out_channels}"

    lift = model.lift
    scales = ", ".join("1" if s == 1 else f"1/{s}" for s in lift.scales)
    c_in, c_lift = lift.lift[0].in_channels, lift.lift[0].out_channels
    x_in, x_lift, x0 = 0.0, 1.7, 3.45
    box(x_in, 0, f"input [x, p]\n{c_in} channels", "#e8e8e8")
    box(x_lift, 0, f"lift\nscales {scales}\n1×1: {c_in}→{c_lift} each\nmix 1×1: "
                   f"{lift.mix.in_channels}→{lift.mix.out_channels}", "#cfe3f5", height=1.05, width=1.5)
    arrow((x_in + w / 2, 0), (x_lift - 0.75, 0))
    arrow((x_lift + 0.75, 0), (x0 - w / 2, 0))
    enc_pos = []
    for i, block in enumerate(model.down):
        x, y = x0 + i * dx, -i * dy
        enc_pos.append((x, y))
        box(x, y, edc_label(block, "bottleneck" if i == levels - 1 else f"encoder {i}"),
            "#f3d9b1" if i == levels - 1 else "#d8ecd0")
        if i > 0:
            px, py = enc_pos[i - 1]
            arrow((px, py - h / 2), (x - w / 2, y), "avg pool 2×", offset=(-0.62, 0.05))
    prev = enc_pos[-1]
    x_dec = None
    for j, (up, dec) in enumerate(zip(model.up, model.dec)):
        i = levels - 2 - j  # level of this decoder stage
        x_dec, y = x0 + (2 * (levels - 1) - i) * dx, -i * dy
        box(x_dec, y, edc_label(dec, f"decoder {i}"), "#d8ecd0")
        arrow((prev[0] + w / 2, prev[1]), (x_dec, y - h / 2),
              f"up {up.in_channels}→{up.out_channels}\n(ConvT 2×, resize)", offset=(0.72, -0.1))
        ex, ey = enc_pos[i]
        skip_c = model.down[i].body[0].loc.out_channels
        arrow((ex + w / 2, ey), (x_dec - w / 2, y), f"skip, {skip_c} ch", ls="--", color="tab:blue",
              offset=(0.0, 0.12))
        prev = (x_dec, y)
    head = model.head
    x_head = (x_dec if x_dec is not None else x0) + 1.55
    x_out = x_head + 1.55
    box(x_head, 0, f"head\n1×1 conv\n{head.in_channels}→{head.out_channels}", "#cfe3f5")
    box(x_out, 0, f"ψ, {head.out_channels} ch\nu = x + B⊙ψ", "#e8e8e8", width=1.35)
    arrow((prev[0] + w / 2, 0), (x_head - w / 2, 0))
    arrow((x_head + w / 2, 0), (x_out - 0.675, 0))
    ax.set_xlim(x_in - w / 2 - 0.1, x_out + 0.775)
    ax.set_ylim(-(levels - 1) * dy - 0.45, 0.6)
    ax.set_axis_off()
    return ax
