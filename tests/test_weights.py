"""The shipped pretrained models: provenance metadata, loading, and basic validity of their maps."""
import json
from dataclasses import asdict

import numpy as np
import pytest

from rfmap.training.config import ModelConfig, get_config
from rfmap.fields.paper import BELTRAMI_MAPS
from rfmap.surrogate import WEIGHTS_DIR, Surrogate, models
from rfmap.fields.random import RandomBeltramiConfig, RandomDensityConfig
from rfmap.tasks import LossWeights

SHIPPED = models()


def test_every_weight_file_has_metadata():
    for p in WEIGHTS_DIR.glob("*.safetensors"):
        assert p.with_suffix(".json").exists(), p


@pytest.mark.parametrize("name", SHIPPED)
def test_metadata_records_provenance(name):
    meta = json.loads((WEIGHTS_DIR / f"{name}.json").read_text())
    cfg = get_config(name, "full")
    # produced by `rfmap train --config NAME --preset full`: the stored configuration is the named preset, up to
    # settings of how the run was executed (threads, time limit, batch workers, which give the same batches) and
    # of its validation (held-out fields, sizes, checkpoint choice), some of which postdate older weights
    stored = dict(meta["config"])
    expected = cfg.to_dict()
    for key in ("threads", "time_limit", "workers", "val_sizes", "val_count", "val_repair", "val_native",
                "select_best", "val_every", "ckpt_every", "val_n"):
        stored.pop(key, None)
        expected.pop(key, None)
    # model fields added after the weights were made (the FNO's) take their defaults, which leave a U-Net unchanged
    stored["model"] = {**asdict(ModelConfig()), **stored["model"]}
    # likewise loss switches added later (density_tangent) default to what older runs did
    stored["loss"] = {**asdict(LossWeights()), **stored["loss"]}
    if stored.get("density_field"):  # and random-field settings added later (ramp_width, ramp_scale, hard fields)
        defaults = json.loads(json.dumps(asdict(RandomDensityConfig())))
        later = ("ramp_width", "ramp_scale", "p_hard", "hard_contrast", "hard_background")
        stored["density_field"] = {**{k: v for k, v in defaults.items() if k in later},
                                   **stored["density_field"]}
    if stored.get("beltrami_field"):  # and the low-frequency share of the random maps, added later
        defaults = json.loads(json.dumps(asdict(RandomBeltramiConfig())))
        later = ("low", "low_modes", "low_freq")
        stored["beltrami_field"] = {**{k: v for k, v in defaults.items() if k in later},
                                    **stored["beltrami_field"]}
    stored.setdefault("ema", 0.0)  # weight averaging, added later (runs before it trained without)
    # the classical teacher and snapshots, added later: runs before them were data-free and wrote none
    stored.setdefault("teacher", {"method": "none", "share": 0.5, "weight": 0.1})
    stored.setdefault("snapshot_every", 0)
    # the size curriculum and growth, added later: runs before them drew sides uniformly at a fixed batch, ungrown
    stored.setdefault("n_sampling", "uniform")
    stored.setdefault("batch_points", 0)
    stored.setdefault("grow", False)
    # the training precision, added later: every shipped run trained on a CPU, in float32
    stored.setdefault("precision", "fp32")
    # a description says what the model is, and is rewritten as the project's words improve; the history is in the
    # lineage, which is checked below
    stored.pop("description", None)
    expected.pop("description", None)
    # overrides given on the recorded command line (e.g. --steps for a warm restart) are what it says they are
    words = meta.get("command", "").split()
    for flag, key, kind in (("--steps", "steps", int), ("--batch", "batch", int), ("--seed", "seed", int),
                            ("--lr", "lr", float), ("--ema", "ema", float), ("--precision", "precision", str),
                            ("--snapshot-every", "snapshot_every", int)):
        if flag in words:
            assert stored[key] == kind(words[words.index(flag) + 1])
            expected[key] = stored[key]
    for flag, key in (("--n-sampling", "n_sampling"), ("--batch-points", "batch_points")):
        if flag in words:
            assert str(stored[key]) == words[words.index(flag) + 1]
            expected[key] = stored[key]
    if "--n-range" in words:
        i = words.index("--n-range")
        assert stored["n_range"] == [int(words[i + 1]), int(words[i + 2])]
        expected["n_range"] = stored["n_range"]
    if "--grow" in words:  # a grown network: the base it was widened to, and its parent in the lineage
        assert stored["grow"] and stored["model"]["base"] == int(words[words.index("--grow") + 1])
        expected["grow"], expected["model"] = True, stored["model"]
        assert any("grown" in rec for rec in meta["lineage"])
    if "--base" in words:  # a grown network trained on at its width: a run of its lineage grew it
        base = int(words[words.index("--base") + 1])
        assert stored["model"]["base"] == base
        if base != expected["model"]["base"]:
            assert any("grown" in rec for rec in meta["lineage"])
        expected["model"] = {**expected["model"], "base": base}
    if "--hard-share" in words:  # the share of hard fields in the random densities
        share = float(words[words.index("--hard-share") + 1])
        assert stored["density_field"]["p_hard"] == share
        expected["density_field"] = {**expected["density_field"], "p_hard": share}
    assert stored == expected
    assert meta["preset"] == "full"
    assert meta["steps"] > 0 and 0 < meta["wall_time"] <= 9000  # one run of at most 150 minutes
    assert meta["command"].startswith(f"rfmap train --config {name}")
    # a warm restart (--init) records its parents: name, SHA-256 and cumulative budget
    lineage = meta.get("lineage", [])
    assert ("--init" in meta["command"]) == bool(lineage)
    for rec in lineage:
        assert len(rec["sha256"]) == 64 and rec["cumulative_steps"] >= rec["steps"] > 0
    if lineage:
        assert meta["cumulative_steps"] == lineage[-1]["cumulative_steps"] + meta["steps"]
    assert "mean" in meta["final_metrics"]
    assert meta["history"]["step"] and meta["history"]["loss"]


@pytest.mark.parametrize("name", SHIPPED)
def test_pretrained_model_maps_without_folding(name):
    """The raw network map (no repair) of a test field, at an odd and an even size, is fold-free, finite and far from
    the identity map, and the delivered map is that map bit for bit: neither the fold repair nor the shortening
    touched it, so no fold and the equalization are the network's own.  (Accuracy bounds per model and field are in
    test_accuracy.py.)"""
    sur = Surrogate.pretrained(name)
    field = "T1" if sur.spec.kind == "beltrami" else ("sin-cos" if sur.spec.dim == 2 else "sin-cos-3d")
    for n in (33, 32) if sur.spec.dim == 2 else (17, 16):
        raw = sur.map(field, n, repair=False)
        res = sur.map(field, n)
        assert np.isfinite(raw.mapped_points).all()
        assert not res.info["repair"]["needed"] and "shorten" not in res.info
        np.testing.assert_array_equal(res.mapped_points, raw.mapped_points)
        if sur.spec.kind == "density":
            m = raw.metrics()
            # measured 0.14-0.25 (U-Nets) and 0.47 (FNO) at both sizes; the identity map has 1
            assert m.n_flipped == 0 and m.std_rho_map < 0.6 * m.std_rho_orig
        else:
            m = raw.metrics(exact_points=BELTRAMI_MAPS[field](raw.ref_points))
            # mean |Δd| measured 0.0030 at both sizes; the identity map has 0.0465 at N = 33
            assert m.n_flipped == 0 and m.mean_dd < 0.01


@pytest.mark.parametrize("name", __import__("rfmap.pretrained", fromlist=["study_models"]).study_models())
def test_study_weights_are_their_configs_full_run(name):
    """A study's weights (rfmap.pretrained.STUDY_WEIGHTS) come from `rfmap train --config NAME --preset full`:
    the stored configuration is the named preset's, up to how the run was executed, and they load."""
    from rfmap.pretrained import STUDY_WEIGHTS, load_or_train

    meta = json.loads((STUDY_WEIGHTS / f"{name}.json").read_text())
    assert meta["command"].startswith(f"rfmap train --config {name} --preset full")
    stored, expected = dict(meta["config"]), get_config(name, "full").to_dict()
    for key in ("threads", "workers", "time_limit"):
        stored.pop(key, None)
        expected.pop(key, None)
    assert stored == json.loads(json.dumps(expected))
    assert meta["steps"] == expected["steps"] and meta.get("wall_time", 0) > 0
    assert name not in models()  # a study's weights are not offered as a model
    sur = load_or_train(name, "full")
    assert sur.name == name and sur.meta["config"]["name"] == name
