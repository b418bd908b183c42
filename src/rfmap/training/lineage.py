r"""The chain of ``rfmap train`` runs behind a weight file, and the commands that train it again.

A shipped model is usually the last run of a chain of continued runs: each run started (``--init``) from the weights
the run before it wrote.  The weights' metadata records the chain (``lineage``: one record per earlier run, parents
first, with its command, steps, wall time and SHA-256) and the last run itself (``command``, ``steps``, ...).  A
recorded command names its parent as it was then, ``--init deq2d-square`` for "the shipped deq2d-square of that
day", which is no longer the file of that name; :func:`repeat_commands` therefore rewrites the chain so that run
``k`` starts from the file run ``k - 1`` wrote, and :func:`retrain_command` gives the one command that trains the
weights again from their parent: a shipped file where the parent's SHA-256 is that of a shipped file, else the
output of the repeated chain's previous run.  Where an earlier run of the chain wrote weights that are shipped
(another model's, or an earlier version kept under its own name), the repeat starts from that file.  Where the last
run kept its parent's weights (validation chose none of its states), the weights are those of the run before it:
:func:`source_run` is the run that trained them, and the runs after it (:func:`idle_runs`) are not repeated.

A repeat trains with the recorded options and seed.  A run stops at its ``--steps`` or its ``--time-limit``,
whichever it reaches first, and its learning-rate schedule follows the further along of the two; on another machine
a run may therefore end at another step or another time than the recorded one, and the weights are those of the
same recipe, not the same bits.

Nothing here imports PyTorch: it reads the weights' metadata only (the ``.json`` file beside each weight file).
"""
from __future__ import annotations

import hashlib
import json
import shlex
from dataclasses import dataclass, field
from pathlib import Path

__all__ = ["Run", "chain", "run_settings", "source_run", "idle_runs", "repeat_command", "repeat_commands", "retrain_command",
           "shipped_ancestor", "shipped_hashes", "load_metadata", "REPEAT_ROOT"]

#: where the repeated runs of a chain write their weights: ``runs/retrain/MODEL/run-K``
REPEAT_ROOT = "runs/retrain"


@dataclass(frozen=True)
class Run:
    """One run of a chain, as its record says.

    Attributes
    ----------
    index : int
        Position in the chain, from 1 (the run without a parent).
    config : str
        The configuration it trained (``--config``); its weights are ``CONFIG.safetensors``.
    command : str
        The command line as recorded.
    steps : int
        Steps it ran.
    wall_time : float
        Seconds it ran.
    sha256 : str or None
        SHA-256 of the weight file it wrote (``None`` for the last run: the file itself).
    kept : int or None
        The step whose weights it kept when validation chose an earlier state than its last (0: its parent's).
    then : list of str
        The commands that continued it: ``--resume`` after an interruption, ``--resume --finish`` to end it early.
    grown : dict or None
        The next run widened these weights (``rfmap.nn.grow``): ``{"from": {...}, "to": {...}}``.
    preset : str or None
        Its preset.
    """

    index: int
    config: str
    command: str
    steps: int
    wall_time: float
    sha256: str | None = None
    kept: int | None = None
    then: list[str] = field(default_factory=list)
    grown: dict | None = None
    preset: str | None = None

    @property
    def weights(self) -> str:
        """The file name of the weights it wrote."""
        return f"{self.config}.safetensors"

    @property
    def finished_early(self) -> bool:
        """Stopped before its budget and ended with ``--resume --finish``."""
        return any("--finish" in shlex.split(c) for c in self.then)


def _option(words: list[str], flag: str) -> str | None:
    return words[words.index(flag) + 1] if flag in words and words.index(flag) + 1 < len(words) else None


def _config_of(record: dict) -> str:
    words = shlex.split(record.get("command") or "")
    return _option(words, "--config") or str(record.get("name", "?"))


def _run(index: int, record: dict, sha: str | None) -> Run:
    steps = int(record.get("steps") or 0)
    kept = record.get("selected_step")
    return Run(index=index, config=_config_of(record), command=str(record.get("command") or ""), steps=steps,
               wall_time=float(record.get("wall_time") or 0.0), sha256=sha,
               kept=None if kept is None or int(kept) == steps else int(kept), then=list(record.get("resumed") or []),
               grown=record.get("grown"), preset=record.get("preset"))


def chain(meta: dict) -> list[Run]:
    """The runs behind weights with metadata ``meta``, parents first; the last is the run that wrote them."""
    runs = [_run(k, r, r.get("sha256")) for k, r in enumerate(meta.get("lineage") or [], 1)]
    return runs + [_run(len(runs) + 1, meta, None)]


def run_settings(meta: dict, preset: dict) -> list[dict]:
    """The budget and peak learning rate of every run of a chain, as its command set them.

    Parameters
    ----------
    meta : dict
        The metadata of the last run's weights.
    preset : dict
        ``steps``, ``time_limit`` (seconds) and ``lr`` of the preset the runs started from, for the runs whose
        command does not set them (``--steps``, ``--time-limit``, ``--lr``).

    Returns
    -------
    list of dict
        Per run, parents first: ``run`` (its index), ``steps`` (run), ``step budget``, ``minutes`` (run),
        ``time limit (min)`` and ``peak lr``.
    """
    rows = []
    for run in chain(meta):
        words = shlex.split(run.command)
        steps, limit, lr = (_option(words, flag) for flag in ("--steps", "--time-limit", "--lr"))
        rows.append({"run": run.index, "steps": run.steps,
                     "step budget": int(steps) if steps else int(preset["steps"]),
                     "minutes": run.wall_time / 60.0,
                     "time limit (min)": (float(limit) if limit else float(preset["time_limit"])) / 60.0,
                     "peak lr": float(lr) if lr else float(preset["lr"])})
    return rows


def source_run(meta: dict) -> Run:
    """The run that trained the weights of metadata ``meta``: the last run of the chain, or, where the last runs each
    kept their parent's weights (``kept == 0``: validation chose no state of theirs), the latest run before them.  A
    run counts as keeping its parent's weights only where it trained the same configuration from a parent that was
    not widened (``grown``), so that its file holds exactly the parent's tensors."""
    runs = chain(meta)
    k = len(runs)
    while k > 1 and runs[k - 1].kept == 0 and runs[k - 1].config == runs[k - 2].config and not runs[k - 2].grown:
        k -= 1
    return runs[k - 1]


def idle_runs(meta: dict) -> list[Run]:
    """The runs after :func:`source_run`: each kept its parent's weights, so none is needed to train the weights
    again (empty where the last run trained them)."""
    return chain(meta)[source_run(meta).index:]


def repeat_command(command: str, *, init: str | None = None, out: str | None = None,
                   preset: str | None = None) -> str:
    """``command`` as a fresh run: ``--resume`` and ``--finish`` dropped, ``--init`` set to ``init`` (or dropped),
    ``--out`` set to ``out`` (or kept), and ``--preset`` added when the command relied on the default (which
    ``RFMAP_SCALE`` can change)."""
    words = shlex.split(command)
    kept: list[str] = []
    skip = False
    for w in words:
        if skip:
            skip = False
        elif w in ("--init", "--out"):
            skip = True  # and its value
        elif w not in ("--resume", "--finish"):
            kept.append(w)
    if preset and "--preset" not in kept:
        at = min(kept.index("--config") + 2, len(kept)) if "--config" in kept else len(kept)
        kept[at:at] = ["--preset", preset]
    if init:
        kept += ["--init", init]
    if out:
        kept += ["--out", out]
    return shlex.join(kept)


def shipped_ancestor(meta: dict, shipped: dict[str, str] | None) -> tuple[int, str] | None:
    """``(k, name)`` of the latest run ``k`` before :func:`source_run` whose weights are a shipped file (their SHA-256
    is that of ``shipped``, ``{sha256: name}``, :func:`shipped_hashes`), or ``None``."""
    for run in reversed(chain(meta)[:source_run(meta).index - 1]):
        if run.sha256 and run.sha256 in (shipped or {}):
            return run.index, shipped[run.sha256]
    return None


def repeat_commands(meta: dict, model: str, shipped: dict[str, str] | None = None,
                    root: str = REPEAT_ROOT) -> list[tuple[Run, str]]:
    """The runs that train the weights again and their commands, in order: run ``k`` writes ``ROOT/MODEL/run-k`` and
    starts from the weights run ``k - 1`` wrote there.  Where an earlier run's weights are shipped
    (:func:`shipped_ancestor`), the list starts after it, from the shipped file (``--init NAME``).  It ends with
    :func:`source_run`: runs after it kept their parent's weights and are left out (:func:`idle_runs`)."""
    runs = chain(meta)
    start = shipped_ancestor(meta, shipped)
    out = []
    for run in runs[start[0] if start else 0:source_run(meta).index]:
        if start and run.index == start[0] + 1:
            init = start[1]
        elif run.index > 1:
            init = f"{root}/{model}/run-{run.index - 1}/{runs[run.index - 2].weights}"
        else:
            init = None
        out.append((run, repeat_command(run.command, init=init, out=f"{root}/{model}/run-{run.index}",
                                        preset=run.preset)))
    return out


def retrain_command(meta: dict, model: str, shipped: dict[str, str] | None = None,
                    root: str = REPEAT_ROOT) -> str:
    """The one command that trains weights ``model`` (metadata ``meta``) again from their parent: the last of
    :func:`repeat_commands` (the command of :func:`source_run`), whose ``--init`` is a shipped model where the parent
    is shipped, else the weights the repeated previous run writes (none for a chain of one run)."""
    return repeat_commands(meta, model, shipped, root)[-1][1]


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def shipped_hashes(weights_dir: Path) -> dict[str, str]:
    """``{sha256: name}`` of the weight files ``NAME.safetensors`` in ``weights_dir``."""
    return {_sha256(p): p.stem for p in sorted(Path(weights_dir).glob("*.safetensors"))}


def load_metadata(weights_dir: Path) -> dict[str, dict]:
    """``{name: metadata}`` of the weight files in ``weights_dir`` that have a ``NAME.json`` beside them."""
    return {p.stem: json.loads(p.with_suffix(".json").read_text(encoding="utf-8"))
            for p in sorted(Path(weights_dir).glob("*.safetensors")) if p.with_suffix(".json").exists()}
