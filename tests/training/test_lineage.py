"""rfmap.training.lineage: the chain behind weights and the commands that train them again."""
from __future__ import annotations

import shlex

from rfmap.surrogate import WEIGHTS_DIR
from rfmap.training.cli import build_parser
from rfmap.training.lineage import (chain, idle_runs, load_metadata, repeat_command, repeat_commands, retrain_command,
                                    shipped_ancestor, shipped_hashes, source_run)


def _meta() -> dict:
    """Three runs: a first run resumed at its start, a warm restart ended early, and the last run."""
    return {
        "lineage": [
            {"command": "rfmap train --config m --preset full --resume", "steps": 100, "wall_time": 60.0,
             "sha256": "aa", "preset": "full"},
            {"command": "rfmap train --config m --steps 900 --init m", "steps": 500, "wall_time": 120.0,
             "sha256": "bb", "preset": "full", "selected_step": 400,
             "resumed": ["rfmap train --config m --steps 900 --init m --resume --finish"],
             "grown": {"from": {"base": 8}, "to": {"base": 16}}},
        ],
        "command": "rfmap train --config m --preset full --lr 1e-05 --grow 16 --init m --out /tmp/x",
        "steps": 300, "wall_time": 30.0, "selected_step": 0, "preset": "full",
    }


def test_repeat_command_is_a_fresh_run_with_its_parent_and_output():
    cmd = repeat_command("rfmap train --config m --steps 9 --init m --out old --resume --finish", init="p.safetensors",
                         out="runs/new", preset="full")
    assert shlex.split(cmd) == ["rfmap", "train", "--config", "m", "--preset", "full", "--steps", "9", "--init",
                                "p.safetensors", "--out", "runs/new"]
    # an explicit preset is kept, none is added twice, and no --init is left without a parent
    assert repeat_command("rfmap train --config m --preset ci --init m", preset="full") == \
        "rfmap train --config m --preset ci"


def test_chain_reads_every_run_parents_first():
    runs = chain(_meta())
    assert [r.index for r in runs] == [1, 2, 3] and [r.config for r in runs] == ["m"] * 3
    assert [r.sha256 for r in runs] == ["aa", "bb", None]
    assert runs[0].kept is None and runs[1].kept == 400 and runs[2].kept == 0
    assert runs[1].finished_early and not runs[0].finished_early
    assert runs[1].grown["to"]["base"] == 16 and runs[1].weights == "m.safetensors"


def test_repeat_commands_start_each_run_from_the_previous_runs_file():
    steps = repeat_commands(_meta(), "m")
    assert [r.index for r, _ in steps] == [1, 2, 3]
    first, second, last = (shlex.split(c) for _, c in steps)
    assert "--resume" not in first and "--init" not in first and first[-1] == "runs/retrain/m/run-1"
    assert second[second.index("--init") + 1] == "runs/retrain/m/run-1/m.safetensors"
    assert "--finish" not in second
    assert last[last.index("--init") + 1] == "runs/retrain/m/run-2/m.safetensors"
    assert "--grow" in last and "/tmp/x" not in last
    assert retrain_command(_meta(), "m") == steps[-1][1]


def _meta_kept_parent() -> dict:
    """Three runs of one configuration, the last of which kept its parent's weights (selected_step 0)."""
    return {
        "lineage": [
            {"command": "rfmap train --config m --preset full", "steps": 100, "wall_time": 60.0, "sha256": "aa",
             "preset": "full"},
            {"command": "rfmap train --config m --preset full --init m", "steps": 500, "wall_time": 120.0,
             "sha256": "bb", "preset": "full"},
        ],
        "command": "rfmap train --config m --preset full --lr 1e-05 --init m",
        "steps": 300, "wall_time": 30.0, "selected_step": 0, "preset": "full",
    }


def test_a_last_run_that_kept_its_parents_weights_is_not_repeated():
    meta = _meta_kept_parent()
    assert source_run(meta).index == 2 and [r.index for r in idle_runs(meta)] == [3]
    steps = repeat_commands(meta, "m")
    assert [r.index for r, _ in steps] == [1, 2]
    assert retrain_command(meta, "m") == steps[-1][1]
    assert shlex.split(steps[-1][1])[-1] == "runs/retrain/m/run-2" and "--lr" not in shlex.split(steps[-1][1])
    # a shipped ancestor is looked for before the run that trained the weights
    assert [r.index for r, _ in repeat_commands(meta, "m", {"aa": "base"})] == [2]
    # the run's weights count as its parent's only where the parent was not widened (then they hold other tensors)
    assert source_run(_meta()).index == 3 and idle_runs(_meta()) == []
    grown = _meta_kept_parent()
    grown["lineage"][1]["grown"] = {"from": {"base": 8}, "to": {"base": 16}}
    assert source_run(grown).index == 3
    other = _meta_kept_parent()
    other["command"] = "rfmap train --config m2 --preset full --init m"
    assert source_run(other).index == 3  # another configuration: its weights have another name


def test_a_shipped_ancestor_shortens_the_repeat():
    shipped = {"aa": "base-model"}
    assert shipped_ancestor(_meta(), shipped) == (1, "base-model")
    steps = repeat_commands(_meta(), "m", shipped)
    assert [r.index for r, _ in steps] == [2, 3]
    assert shlex.split(steps[0][1])[shlex.split(steps[0][1]).index("--init") + 1] == "base-model"
    assert shipped_ancestor(_meta(), {"bb": "m"}) == (2, "m")
    assert "--init m --out" in retrain_command(_meta(), "m", {"bb": "m"})
    assert shipped_ancestor(_meta(), {}) is None


def test_every_shipped_model_has_a_command_that_rfmap_train_accepts():
    """The command that trains each shipped weight file again parses with rfmap train's own parser, names the
    weights' configuration, and starts from a shipped model or from the file of the repeated run before it."""
    metas = load_metadata(WEIGHTS_DIR)
    shipped = shipped_hashes(WEIGHTS_DIR)
    assert metas and set(shipped.values()) == set(metas)
    parser = build_parser()
    for name, meta in metas.items():
        steps = repeat_commands(meta, name, shipped)
        assert steps and steps[-1][0] == source_run(meta)
        assert [r.index for r in idle_runs(meta)] == list(range(source_run(meta).index + 1, len(chain(meta)) + 1))
        assert all(r.kept == 0 for r in idle_runs(meta))  # a run left out kept its parent's weights
        for run, command in steps:
            words = shlex.split(command)
            assert words[:2] == ["rfmap", "train"] and "--resume" not in words
            args = parser.parse_args(words[2:])
            assert args.config == run.config and args.preset == "full"
            assert args.init is None or args.init in metas or args.init.startswith(f"runs/retrain/{name}/run-")
        assert steps[-1][0].config == name  # the last run trained the shipped configuration


def test_run_settings_reads_each_run_s_overrides_and_falls_back_to_the_preset():
    from rfmap.training.lineage import run_settings

    meta = {"command": "rfmap train --config m --preset full --steps 900 --lr 0.0001 --init m", "steps": 800,
            "wall_time": 600.0,
            "lineage": [{"command": "rfmap train --config m --preset full", "steps": 100, "wall_time": 1200.0}]}
    rows = run_settings(meta, {"steps": 500, "time_limit": 1800.0, "lr": 5e-4})
    assert [r["run"] for r in rows] == [1, 2]
    assert (rows[0]["step budget"], rows[0]["time limit (min)"], rows[0]["peak lr"]) == (500, 30.0, 5e-4)
    assert (rows[1]["step budget"], rows[1]["time limit (min)"], rows[1]["peak lr"]) == (900, 30.0, 1e-4)
    assert rows[0]["minutes"] == 20.0 and rows[1]["steps"] == 800
