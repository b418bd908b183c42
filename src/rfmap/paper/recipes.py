r"""How the shipped models were trained, from their metadata: the training fields in words and the recipe table."""
from __future__ import annotations

from ..tasks import get_task
from ..training.config import PRESETS, get_config
from ..training.validation import score_parts
from .comparison import format_time
from .tables import Table, decimal_text, rate_text

__all__ = ["training_fields_text", "recipe_table", "recipe_markdown", "recipe_differences", "differences_text",
           "differences_table", "training_settings", "settings_markdown", "preset_markdown", "chain_markdown"]


def training_fields_text(config: dict) -> str:
    """The random training fields of a stored training configuration (``meta["config"]``) in words, as its task
    describes them (``Task.training_fields_text``)."""
    return get_task(config["task"]["kind"]).training_fields_text(config)


def recipe_table(surs: dict) -> Table:
    r"""How each model was trained, from its metadata, one row per model and one column per item:

    * ``fields``: the training fields (:func:`training_fields_text`);
    * ``fold``: the fold penalty, its weight and the threshold :math:`\tau` of :math:`\det J < \tau` below which it
      acts;
    * ``lr``: the peak learning rate of the last run;
    * ``ema``: the decay of its weight average (``None`` where the weights shipped as trained);
    * ``steps`` and ``train_time``: the steps and minutes summed over the model's chain of runs (``--init``);
    * ``val_n``: the grid sides of the held-out validation of the shipped weights, as recorded at the end of training
      (:func:`rfmap.training.validation.evaluate`);
    * ``held_out``: the score that chose the kept weights, as :func:`rfmap.training.validation.score` ranks the
      validation's scores;
    * ``score_kind``: what that score is, one of the checkpoint score (Std ratio by family), the mean metric with
      every folded map counted as the identity map, the capped mean and the plain mean;
    * ``scored``: which maps were scored: the ``raw`` network output, or the ``default`` maps as a plain
      ``Surrogate.map`` returns them, a folded map regridded or repaired (``TrainConfig.val_repair``);
    * ``folded_maps``: how many held-out maps the network itself folded.

    The validation sides differ between models (``val_n``): the held-out scores of models validated on different
    sides are not comparable.

    Each column of the Markdown table is in one notation: rates as powers of ten
    (:func:`~rfmap.paper.tables.rate_text`), steps with thousands separators, minutes whole, the held-out scores with
    three significant digits in positional notation (:func:`~rfmap.paper.tables.decimal_text`)."""
    t = Table("tab:recipes", "How the models were trained",
              ["fields", "fold", "lr", "ema", "steps", "train_time", "val_n", "held_out", "score_kind", "scored",
               "folded_maps"],
              formats={"lr": rate_text, "steps": lambda v: f"{int(v):,}", "train_time": lambda v: f"{float(v):,.0f}",
                       "held_out": decimal_text})
    for name, s in surs.items():
        meta = s.meta
        cfg = meta.get("config") or {}
        loss = cfg.get("loss") or {}
        val = (meta.get("final_metrics") or {}).get("mean") or {}
        metric, kind = _selection(val)
        t.add(name, s.model.kwargs().get("arch", "unet"), {
            "fields": training_fields_text(cfg) if cfg else None,
            "fold": f"{loss.get('fold', 10.0):g} from {loss.get('fold_threshold', 0.02):g}" if cfg else None,
            "lr": float(cfg["lr"]) if "lr" in cfg else None,
            "ema": float(cfg["ema"]) if cfg.get("ema") else None,
            "steps": int(meta.get("cumulative_steps", meta.get("steps", 0))),
            "train_time": float(meta.get("cumulative_wall_time", meta.get("wall_time", 0.0))) / 60.0,
            "val_n": "/".join(str(n) for n in (cfg.get("val_sizes") or [cfg.get("val_n", "?")])) if cfg else None,
            "held_out": None if metric is None else float(metric),
            "score_kind": kind,
            "scored": ("default" if val.get("path") == "repaired" else "raw") if val else None,
            "folded_maps": _folded_maps(meta.get("final_metrics") or {})})
    return t


def _folded_maps(metrics: dict) -> int | None:
    """How many held-out maps the network folded, from a validation record (``final_metrics``): the count its summary
    records, else the fields whose own entries record flipped elements, else ``None``."""
    val = metrics.get("mean") or {}
    for key in ("raw_folded_fields", "folded_fields"):
        if key in val:
            return int(val[key])
    fields = [v for k, v in metrics.items() if k != "mean" and isinstance(v, dict) and "n_flipped" in v]
    return sum(int(v["n_flipped"]) > 0 for v in fields) if fields else None


#: The recipe table in three narrow parts (what a model learned from, how it was optimised, how it was validated):
#: each part's columns with their headers.
RECIPE_PARTS = {
    "Training fields and fold penalty": {"fields": "training fields", "fold": "fold penalty"},
    "Optimisation over the whole chain (learning rate and weight average of the last run)":
        {"lr": "peak lr", "ema": "weight average", "steps": "steps", "train_time": "minutes"},
    "Held-out validation of the kept weights":
        {"val_n": "N", "held_out": "score", "score_kind": "what the score is", "scored": "maps scored",
         "folded_maps": "folded maps"},
}


#: What the columns of each part of :data:`RECIPE_PARTS` mean, printed under its table.
RECIPE_LEGENDS = {
    "Training fields and fold penalty":
        "*training fields*: the smooth modes that every field has, then the share of fields that add each other "
        "feature (a box step is a jump of the density, not an optimiser step); *fold penalty*: its weight, then "
        "the det J below which it acts (1 from 0.02: weight 1 below det J = 0.02).",
    "Optimisation over the whole chain (learning rate and weight average of the last run)":
        "*peak lr*: the top of the last run's learning-rate schedule; *weight average*: the decay of the "
        "exponential moving average of the weights it shipped (none: the weights as trained); *steps* and "
        "*minutes*: summed over every run of the chain.",
    "Held-out validation of the kept weights":
        "*N*: the held-out grid sides; *score*: the validation score of the kept weights, lower is better; "
        "*maps scored*: the raw network maps, or the default maps a plain Surrogate.map returns; *folded maps*: "
        "held-out maps the network itself folded at the kept weights (the default maps repair them; the chapter "
        "on bijectivity shows how).",
}

#: The note added under a part of :func:`recipe_markdown` whose table shows a dash.
_MISSING_NOTE = "—: not recorded in the model's metadata."


def recipe_markdown(table: Table) -> str:
    """A :func:`recipe_table` as three Markdown tables of a few columns each (:data:`RECIPE_PARTS`), one row per
    model, so that each fits the width of a book page, each followed by the legend of its columns
    (:data:`RECIPE_LEGENDS`). A weight average that is absent reads "none" (the weights as trained); any other
    absent value reads "—", and the legend of a part explains the dash only where its table shows one
    ("—: not recorded in the model's metadata")."""
    out = []
    for title, cols in RECIPE_PARTS.items():
        lines = [f"**{title}**", "", "| model | " + " | ".join(cols.values()) + " |", "|" + "---|" * (len(cols) + 1)]
        dashed = False
        for case, _, values in table.rows:
            cells = ["none" if c == "ema" and values.get(c) is None
                     else table.cell(values.get(c), c).replace("|", "\\|") for c in cols]
            dashed = dashed or "—" in cells
            lines.append(f"| {case} | " + " | ".join(cells) + " |")
        legend = RECIPE_LEGENDS[title] + (" " + _MISSING_NOTE if dashed else "")
        lines += ["", legend]
        out.append("\n".join(lines))
    return "\n\n".join(out)


def _selection(val: dict) -> tuple[float | None, str | None]:
    """The score that chose the kept weights, from a validation summary, and what it is, as
    :func:`rfmap.training.validation.score_parts` ranks them: the checkpoint score (each field's Std(ρ̃_map)
    relative to its Std(ρ̃_orig), averaged by family) where recorded, else the mean metric with every folded map
    counted as the identity, else the plain mean."""
    if not val:
        return None, None
    metric = "|Δd|" if "mean_dd" in val else "Std"
    try:
        _, value, what = score_parts(val)
    except KeyError:  # no metric recorded at all
        return None, None
    return value, {"family_score": "Std ratio by family", "penalized": f"mean {metric}, folds as identity",
                   "capped": f"mean {metric}, folds as identity", "mean": f"mean {metric}"}[what]


#: The settings of a stored training configuration that name or time a run rather than shape what it learns.
RUN_SETTINGS = ("name", "description", "seed", "steps", "time_limit", "out", "init")
#: How :func:`differences_text` names a setting: a dotted key of the stored configuration (``"loss.beltrami"``,
#: ``"lr"``, ``"ema"``, ``"loss.fold"``, ``"n_range"``, ``"batch"``) -> its name in the text
#: (``"Beltrami weight λ_hr"``, ``"peak learning rate"``, ...); a setting not listed is named by its key.
SETTING_NAMES = {"loss.beltrami": "Beltrami weight λ_hr", "lr": "peak learning rate", "ema": "weight average decay",
                 "loss.fold": "fold penalty", "n_range": "training grid sides", "batch": "batch"}


def recipe_differences(a: dict, b: dict, prefix: str = "") -> list[tuple[str, object, object]]:
    """The settings in which two stored training configurations (``meta["config"]``) differ, as ``(dotted key,
    value in a, value in b)``, nested sections flattened, the settings of :data:`RUN_SETTINGS` left out."""
    out = []
    for key in sorted(set(a) | set(b)):
        if key in RUN_SETTINGS:
            continue
        va, vb = a.get(key), b.get(key)
        if f"{prefix}{key}" == "model" and isinstance(va, dict) and isinstance(vb, dict):
            va, vb = _network_settings(va), _network_settings(vb)
        if isinstance(va, dict) and isinstance(vb, dict):
            out += recipe_differences(va, vb, f"{prefix}{key}.")
        elif va != vb:
            out.append((f"{prefix}{key}", va, vb))
    return out


#: the settings of each network that apply to it (a stored model section holds every architecture's fields)
_NETWORK_SETTINGS = {"unet": ("arch", "base", "depth", "attention"),
                     "fno": ("arch", "modes", "width", "layers", "padding")}


def _network_settings(model: dict) -> dict:
    """The part of a stored ``model`` section that its architecture uses (unknown architectures: all of it)."""
    keep = _NETWORK_SETTINGS.get(model.get("arch", "unet"))
    return dict(model) if keep is None else {k: model[k] for k in keep if k in model}


def differences_text(metas: dict) -> str:
    """How two shipped models' training differs, in words, from their metadata (``{name: meta}``): every setting of
    :func:`recipe_differences` and the cumulative steps over each model's chain of continued runs (``--init``)."""
    (na, ma), (nb, mb) = metas.items()
    parts = [f"{SETTING_NAMES.get(k, k)} ({'none' if x is None else x} against {'none' if y is None else y})"
             for k, x, y in recipe_differences(ma.get("config") or {}, mb.get("config") or {})]
    steps = [int(m.get("cumulative_steps", m.get("steps", 0))) for m in (ma, mb)]
    parts.append(f"training steps ({steps[0]:,} against {steps[1]:,})")
    return f"`{na}` and `{nb}` differ in " + ", ".join(parts[:-1]) + (" and " if len(parts) > 1 else "") + parts[-1]


def _setting_value(v) -> str:
    if v is None:
        return "—"
    if isinstance(v, (list, tuple)):
        return " to ".join(_setting_value(x) for x in v) if len(v) == 2 else ", ".join(map(_setting_value, v))
    if isinstance(v, float):
        return f"{v:g}"
    return str(v)


def differences_table(metas: dict) -> str:
    """How two shipped models' training differs, from their metadata (``{name: meta}``), as a Markdown table: one
    row per setting of :func:`recipe_differences` (named as :data:`SETTING_NAMES` names it, else by its dotted
    key), one column per model ("—": the setting is absent, i.e. off), the cumulative steps over each model's chain
    of continued runs last."""
    (na, ma), (nb, mb) = metas.items()
    rows = [(SETTING_NAMES.get(k, f"`{k}`"), _setting_value(x), _setting_value(y))
            for k, x, y in recipe_differences(ma.get("config") or {}, mb.get("config") or {})]
    steps = [int(m.get("cumulative_steps", m.get("steps", 0))) for m in (ma, mb)]
    rows.append(("training steps (cumulative)", f"{steps[0]:,}", f"{steps[1]:,}"))
    lines = [f"| setting | `{na}` | `{nb}` |", "|---|---|---|"]
    lines += [f"| {k} | {x} | {y} |" for k, x, y in rows]
    return "\n".join(lines)


def training_settings(meta: dict) -> dict[str, str]:
    r"""The settings of a model's training that the book's chapter "08 DEM against DEQ on an extreme density"
    compares, in words, from its metadata (``Surrogate.meta``): the Beltrami weight λ_hr, the fold penalty (its weight
    and the threshold of :math:`\det J` below which it acts), the decay of the weight average, the peak learning
    rate and the seed of the last run, and the steps over its ``--init`` chain (``cumulative_steps``; its earlier
    runs are ``lineage``).

    Examples
    --------
    >>> config = {"loss": {"beltrami": 0.1}, "ema": 0.0, "lr": 5e-4, "seed": 0}
    >>> training_settings({"config": config, "steps": 3000})["training steps"]
    '3,000 in 1 run'
    """
    cfg = meta["config"]
    runs = len(meta.get("lineage", [])) + 1
    steps = meta.get("cumulative_steps", meta["steps"])
    loss = cfg["loss"]
    return {"Beltrami weight λ_hr": f"{loss['beltrami']:g}",
            "fold penalty": f"{loss.get('fold', 10.0):g} where det J < {loss.get('fold_threshold', 0.02):g}",
            "weight average (EMA decay)": f"{cfg['ema']:g}" if cfg.get("ema") else "none",
            "peak learning rate of the last run": rate_text(cfg["lr"]),
            "seed of the last run": str(cfg["seed"]),
            "training steps": f"{steps:,} in {runs} run" + ("s" if runs != 1 else "")}


def settings_markdown(metas: dict) -> str:
    """A Markdown table of :func:`training_settings`, one column per model (``{name: meta}``)."""
    rows = {name: training_settings(m) for name, m in metas.items()}
    first = next(iter(rows.values()))
    lines = ["| setting | " + " | ".join(rows) + " |", "|---" * (len(rows) + 1) + "|"]
    lines += [f"| {k} | " + " | ".join(r[k] for r in rows.values()) + " |" for k in first]
    return "\n".join(lines)


def _markdown(header: list[str], rows: list[list]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|---" * len(header) + "|"]
    return "\n".join(lines + ["| " + " | ".join(map(str, row)) + " |" for row in rows])


def preset_markdown(name: str) -> str:
    """The presets of training configuration ``name`` side by side (Markdown, one row per preset): steps, batch,
    grid sides, peak learning rate, weight decay, schedule and time limit ("none" where it has none)."""
    rows = []
    for preset in PRESETS:
        c = get_config(name, preset)
        rows.append([preset, f"{c.steps:,}", c.batch, f"{c.n_range[0]}–{c.n_range[1]}", rate_text(c.lr),
                     rate_text(c.weight_decay), c.schedule, format_time(c.time_limit) if c.time_limit else "none"])
    return _markdown(["preset", "steps", "batch", "N", "peak lr", "weight decay", "schedule", "time limit"], rows)


def chain_markdown(runs: list[dict]) -> str:
    """The runs of a chain (:func:`rfmap.training.lineage.run_settings`) as Markdown, one row per run: its step
    budget, time limit and peak learning rate as its command set them, and the steps and minutes it ran."""
    rows = [[r["run"], f"{r['step budget']:,}", f"{r['time limit (min)']:.0f} min", rate_text(r["peak lr"]),
             f"{r['steps']:,}", f"{r['minutes']:.0f}"] for r in runs]
    return _markdown(["run", "step budget", "time limit", "peak lr", "steps run", "minutes run"], rows)
