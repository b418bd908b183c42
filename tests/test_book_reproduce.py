"""book/reproduce.md: its retraining section is generated from the shipped weights' metadata and is up to date;
its account of scripts/device_train.sh matches the script's defaults."""
from __future__ import annotations

import importlib.util
import re
import shlex
from pathlib import Path

from rfmap.surrogate import WEIGHTS_DIR
from rfmap.training.lineage import load_metadata, retrain_command, shipped_hashes

ROOT = Path(__file__).resolve().parent.parent
PAGE = ROOT / "book" / "reproduce.md"


def _script():
    spec = importlib.util.spec_from_file_location("make_reproduce_md", ROOT / "scripts" / "make_reproduce_md.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_reproduce_page_is_up_to_date():
    mod = _script()
    assert PAGE.read_text(encoding="utf-8") == mod.page(), "book/reproduce.md is stale: run make pages"
    assert mod.main(["--check"]) == 0
    assert "$(BIN)/python scripts/make_reproduce_md.py" in (ROOT / "Makefile").read_text(encoding="utf-8")


def test_every_shipped_model_has_its_retraining_command_on_the_page():
    text = PAGE.read_text(encoding="utf-8")
    # the shell blocks, their continuation lines joined
    blocks = [shlex.split(b.replace("\\\n", " "), comments=True)
              for b in re.findall(r"```bash\n(.*?)```", text, re.S)]
    commands = [b for b in blocks if b[:2] == ["rfmap", "train"]]
    shipped = shipped_hashes(WEIGHTS_DIR)
    for name, meta in load_metadata(WEIGHTS_DIR).items():
        assert f"(retrain-{name})=" in text and f"| [{name}](retrain-{name}) |" in text, name
        assert shlex.split(retrain_command(meta, name, shipped)) in commands, name


def test_wrap_keeps_the_words():
    wrap = _script().wrap
    cmd = ("rfmap train --config dem3d-cube-native --preset full --time-limit 4200 --threads 1 --lr 3e-05 "
           "--n-range 32 64 --val-sizes 48 64 --init runs/retrain/x/run-12/dem3d-cube-native.safetensors "
           "--out runs/retrain/x/run-13")
    lines = wrap(cmd, width=60).split("\n")
    assert len(lines) > 1 and all(line.endswith(" \\") for line in lines[:-1])
    assert shlex.split(wrap(cmd, width=60).replace("\\\n", " ")) == shlex.split(cmd)


def test_the_gpu_section_states_device_train_defaults():
    """The command the page shows for scripts/device_train.sh carries the script's own defaults."""
    script = (ROOT / "scripts" / "device_train.sh").read_text(encoding="utf-8")
    defaults = dict(re.findall(r"^([A-Z_]+)=\$\{\1:-([^}]*)\}", script, re.M))
    text = PAGE.read_text(encoding="utf-8")
    shown = re.search(r"python -m rfmap\.training (.*?)\$TRAIN_ARGS", text, re.S).group(1).replace("\\\n", " ")
    words = shlex.split(shown)
    for flag, var in [("--preset", "PRESET"), ("--device", "DEVICE"), ("--precision", "PRECISION"),
                      ("--threads", "THREADS"), ("--workers", "WORKERS"), ("--snapshot-every", "SNAPSHOT_EVERY")]:
        assert words[words.index(flag) + 1] == defaults[var], (flag, defaults[var])
        assert f"`{var}`" in text
    assert "--no-validate" in words and "--no-validate" in script
    # the two caps the page explains are the script's: MINUTES at most 8, at most 8 files back
    assert "if not 0 < m <= 8:" in script and "-le 8 ]" in script
    assert "caps the minutes at 8 in all and the files it keeps at 8" in " ".join(text.split())
    assert "--grow" in script and "twice as wide as\nany shipped one" in text


def test_the_page_says_what_a_repeat_gives_and_costs():
    """Retraining repeats chains of runs stopped on the clock: comparable weights, not identical ones, and the wall
    and CPU time of the runs to repeat, computed from the metadata; no build-tool internals in the prose."""
    mod = _script()
    text = PAGE.read_text(encoding="utf-8")
    metas, shipped = load_metadata(WEIGHTS_DIR), shipped_hashes(WEIGHTS_DIR)
    cost = "\n".join(mod._repeat_cost(metas, shipped))
    assert cost.strip() in text and "not identical" in cost and "CPU time" in cost
    runs = sum(len(mod.repeat_commands(m, name, shipped)) for name, m in metas.items())
    assert f"repeating {runs} runs" in cost
    assert "untimed first run" not in text
    for internal in ("environment.pickle", ".doctrees", "{glue:text}", ".installed"):
        assert internal not in text, internal


def test_the_gpu_example_is_a_shipped_command_with_the_gpu_options():
    """The GPU example is deq2d-square's retraining command as the page's generated section gives it, followed by
    the device, precision and thread options, so it can be copied as it stands and cannot drift from the record."""
    text = PAGE.read_text(encoding="utf-8")
    block = re.search(r"add the device and precision at the end.*?```bash\n(.*?)```", text, re.S).group(1)
    words = shlex.split(block.replace("\\\n", " "))
    meta = load_metadata(WEIGHTS_DIR)["deq2d-square"]
    recorded = shlex.split(retrain_command(meta, "deq2d-square", shipped_hashes(WEIGHTS_DIR)))
    assert "..." not in words
    assert words == recorded + ["--device", "cuda", "--precision", "bf16", "--threads", "4", "--workers", "8"]
