"""How two shipped models' training differs, from their stored configurations (rfmap.paper.recipes)."""
from rfmap.paper.recipes import differences_text, recipe_differences


def test_differences_leave_out_run_settings_and_flatten_sections():
    a = {"name": "a", "seed": 1, "steps": 10, "lr": 2e-4, "ema": None, "loss": {"beltrami": 0.0, "fold": 100}}
    b = {"name": "b", "seed": 2, "steps": 20, "lr": 7e-5, "ema": 0.999, "loss": {"beltrami": 0.1, "fold": 100}}
    assert recipe_differences(a, b) == [("ema", None, 0.999), ("loss.beltrami", 0.0, 0.1), ("lr", 2e-4, 7e-5)]
    text = differences_text({"a": {"config": a, "cumulative_steps": 1000}, "b": {"config": b, "steps": 20}})
    assert text.startswith("`a` and `b` differ in weight average decay (none against 0.999), Beltrami weight λ")
    assert text.endswith("and training steps (1,000 against 20)")
    assert differences_text({"a": {"config": a}, "b": {"config": a}}) == "`a` and `b` differ in training steps (0 against 0)"
