"""The sentences of the budget section of chapter 16 (appendix C): how each shipped model's steps compare with the
paper's epochs, which shipped states come before the end of their run, and how often the raw maps of the validated
states fold.

Each function reads the training records (a model's metadata: the ``meta`` dictionary of a loaded
:class:`rfmap.Surrogate`) and returns text; :func:`budget_glue` returns them all under the names the appendix
glues them by.
"""
from __future__ import annotations

from ..training.validation import has_folds, score_parts
from .compare import shipped_raw_folds, validated_states

__all__ = ["names_text", "times_text", "budget_sentences", "kept_early_text", "raw_folds_text", "fold_states_text",
           "scored_text", "budget_glue"]

WORDS = dict(enumerate(["no", "one", "two", "three", "four", "five", "six", "seven", "eight"]))


def names_text(names) -> str:
    """Names as a sentence lists them: ``'none'``, ``'a'``, ``'a and b'``, ``'a, b and c'``."""
    names = list(names)
    return "none" if not names else names[0] if len(names) == 1 else (", ".join(names[:-1]) + " and " + names[-1])


def times_text(ratio: float) -> str:
    """A multiple of the paper's epochs: three significant digits from 10 on (25.5), two below (4.4)."""
    return f"{ratio:.3g}" if ratio >= 10 else f"{ratio:.2g}"


def budget_sentences(steps: dict, paper_steps: dict) -> dict[str, str]:
    """The models' steps against the paper's epochs read as steps.

    Parameters
    ----------
    steps, paper_steps : dict
        Per model name, the steps its chain spent and the paper's epochs.

    Returns
    -------
    dict
        ``budget_text``, the sentence of the section (which models ran past the paper's epochs, by how much, and
        what share the others reached), and ``budget_summary``, its clause for the summary.
    """
    ratio = {k: steps[k] / paper_steps[k] for k in steps}
    over = [k for k in steps if ratio[k] > 1]
    under = [k for k in steps if k not in over]
    lo, hi = min(ratio[k] for k in over or steps), max(ratio[k] for k in over or steps)
    lo_t, hi_t = times_text(lo), times_text(hi)
    spread = f"{lo_t} times as many" if lo_t == hi_t else f"from {lo_t} to {hi_t} times as many"
    short = "; ".join(f"{k} made {100 * ratio[k]:.0f} % of the paper's {paper_steps[k]:,}" for k in under)
    if not under:
        text = f"Every model made more steps than the paper's epochs, read as steps: {spread}."
    elif not over:
        text = f"Every model made fewer steps than the paper's epochs, read as steps: {short}."
    else:
        text = (f"Every model except {names_text(under)} made more steps than the paper's epochs, read as steps, "
                f"{spread}; {short}.")
    factor = lo_t if lo_t == hi_t else f"{lo_t} to {hi_t}"
    summary = (f"every model ran past the paper's epochs, by {factor} times" if not under
               else "no model reached the paper's epochs" if not over
               else f"every model but {names_text(under)} ran past the paper's epochs, by {factor} times")
    return {"budget_text": text, "budget_summary": summary}


def kept_early_text(metas: dict) -> str:
    """Which models ship a state from before the end of their last run, and which the state it started from."""
    early = [k for k, m in metas.items() if m.get("selected_step", m.get("steps")) < m.get("steps", 0)]
    at_start = [k for k, m in metas.items() if m.get("selected_step") == 0]
    text = ("Every model ships the last state of its last run." if not early else
            ("For every model" if len(early) == len(metas) else f"For {names_text(early)}")
            + " the shipped state comes before the end of the last run, so the shipped weights hold fewer steps "
            "than the chain spent.")
    if at_start:
        text += (f" For {names_text(at_start)} it is the state the last run started from: that run never improved "
                 "on the weights it continued from, and those weights were shipped.")
    return text


def raw_folds_text(raw_folds_of: dict) -> str:
    """The budget table's last column in words: on how many validation fields each shipped raw map folds.

    ``raw_folds_of`` maps each model to ``(folded fields, fields)``, as :func:`rfmap.paper.compare.shipped_raw_folds`
    returns them."""
    counts = [f"{a} of {b} for {k}" for k, (a, b) in raw_folds_of.items() if a]
    rest = len(raw_folds_of) - len(counts)
    if not counts:
        return "The raw map of no shipped model folds on its validation fields."
    return ("The raw map of the shipped weights folds on "
            + names_text([counts[0].replace(" for ", " validation fields for ", 1)] + counts[1:])
            + (f", and on none for the other {_models(rest)}." if rest else "."))


def _models(k: int) -> str:
    """``k`` models in words: "one model", "two models", …"""
    return f"{WORDS.get(k, k)} model" + ("" if k == 1 else "s")


def fold_states_text(metas: dict) -> str:
    """The models whose raw map folded at every validated state of the last run, at none, or at some."""
    folded_at = {k: [has_folds(v, raw=True) for v in validated_states(m)] for k, m in metas.items()}
    every = [k for k, f in folded_at.items() if f and all(f)]
    never = [k for k, f in folded_at.items() if not any(f)]
    some = [k for k in metas if k not in every + never]

    def raw_of(names):
        return ("the raw maps of " if len(names) > 1 else "the raw map of ") + names_text(names)

    parts = []
    if every:
        parts.append(raw_of(every) + " folded on some validation field at every validated state of the last run")
    if never:
        parts.append(raw_of(never) + " folded at no validated state" + ("" if every else " of the last run"))
    if some:
        other = "that of the other model" if len(some) == 1 else f"those of the other {_models(len(some))}"
        parts.append(other + " at some states only" if parts
                     else raw_of(some) + " folded at some validated states of the last run only")
    text = "; ".join(parts)
    return text[0].upper() + text[1:] + "."


def scored_text(metas: dict) -> str:
    """Which map the runs scored: the repaired map (runs that record the raw folds apart) or the raw one, a folded
    raw map counting as the identity; empty where every run scored the raw map."""
    repaired = [k for k, m in metas.items()
                if any("raw_folded_fields" in v for v in m["history"]["validation"])]
    if not repaired:
        return ""
    as_identity = all(score_parts(metas[k]["history"]["validation"][-1])[2] in ("family_score", "penalized")
                      for k in metas if k not in repaired)
    return (f"The runs of {names_text(repaired)} scored the map a user gets by default, repaired so that it does "
            "not fold, so a fold of the raw map did not count against a state"
            + ("; the other runs scored the raw map, a folded map counting as the identity." if as_identity
               else "."))


def budget_glue(metas: dict, steps: dict, paper_steps: dict) -> dict[str, str]:
    """Every sentence of the budget section under its glue name: ``budget_text``, ``budget_summary``,
    ``kept_early``, ``budget_fold_text``, ``budget_fold_<model>`` for the 3D models (``'a of b'``),
    ``budget_states_text`` and ``budget_scored_text``.

    Parameters
    ----------
    metas : dict
        The shipped models' metadata, by name.
    steps, paper_steps : dict
        Per model, the steps its chain spent and the paper's epochs.
    """
    raw_folds_of = {k: shipped_raw_folds(m) for k, m in metas.items()}
    out = budget_sentences(steps, paper_steps)
    out["kept_early"] = kept_early_text(metas)
    out["budget_fold_text"] = raw_folds_text(raw_folds_of)
    for key in ("dem3d-cube", "dem3d-free"):
        if key in raw_folds_of:
            out[f"budget_fold_{key}"] = "{} of {}".format(*raw_folds_of[key])
    out["budget_states_text"] = fold_states_text(metas)
    out["budget_scored_text"] = scored_text(metas)
    return out
