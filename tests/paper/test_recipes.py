"""How two shipped models' training differs, from their stored configurations (rfmap.paper.recipes)."""
from rfmap.paper.recipes import differences_text, recipe_differences


def test_differences_leave_out_run_settings_and_flatten_sections():
    a = {"name": "a", "seed": 1, "steps": 10, "lr": 2e-4, "ema": None, "loss": {"beltrami": 0.0, "fold": 100}}
    b = {"name": "b", "seed": 2, "steps": 20, "lr": 7e-5, "ema": 0.999, "loss": {"beltrami": 0.1, "fold": 100}}
    assert recipe_differences(a, b) == [("ema", None, 0.999), ("loss.beltrami", 0.0, 0.1), ("lr", 2e-4, 7e-5)]
    text = differences_text({"a": {"config": a, "cumulative_steps": 1000}, "b": {"config": b, "steps": 20}})
    assert text.startswith("`a` and `b` differ in weight average decay (none against 0.999), Beltrami weight λ_hr")
    assert text.endswith("and training steps (1,000 against 20)")
    assert differences_text({"a": {"config": a}, "b": {"config": a}}) == "`a` and `b` differ in training steps (0 against 0)"


def test_differences_table_has_a_row_per_setting_and_a_column_per_model():
    from rfmap.paper.recipes import differences_table

    a = {"name": "a", "lr": 2e-4, "ema": None, "n_range": [48, 96]}
    b = {"name": "b", "lr": 7e-5, "ema": 0.999, "n_range": [64, 96]}
    md = differences_table({"a": {"config": a, "cumulative_steps": 1000}, "b": {"config": b, "steps": 20}})
    lines = md.splitlines()
    assert lines[0] == "| setting | `a` | `b` |"
    assert "| weight average decay | — | 0.999 |" in lines
    assert "| training grid sides | 48 to 96 | 64 to 96 |" in lines
    assert lines[-1] == "| training steps (cumulative) | 1,000 | 20 |"


def test_a_network_section_shows_only_the_settings_of_its_architecture():
    from rfmap.paper.recipes import recipe_differences

    unet = {"model": {"arch": "unet", "base": 16, "depth": 3, "attention": True, "modes": 12, "width": 32}}
    fno = {"model": {"arch": "fno", "base": 16, "depth": 3, "attention": True, "modes": 16, "width": 24}}
    diff = {k: (x, y) for k, x, y in recipe_differences(unet, fno)}
    assert diff["model.arch"] == ("unet", "fno")
    assert diff["model.modes"] == (None, 16) and diff["model.width"] == (None, 24)  # not the U-Net's
    assert diff["model.base"] == (16, None) and "model.depth" in diff
    same = {"model": {"arch": "unet", "base": 16, "depth": 3, "attention": True, "modes": 12}}
    assert recipe_differences(same, {"model": {**same["model"], "modes": 99}}) == []  # unused field ignored


def test_folded_maps_are_counted_from_the_fields_where_the_summary_lacks_them():
    from rfmap.paper.recipes import _folded_maps

    assert _folded_maps({"mean": {"raw_folded_fields": 3, "folded_fields": 1}}) == 3
    record = {"mean": {"n_flipped": 2}, "a@51": {"n_flipped": 0}, "b@51": {"n_flipped": 2}}
    assert _folded_maps(record) == 1
    assert _folded_maps({"mean": {"std_rho_map": 0.1}}) is None and _folded_maps({}) is None


def test_recipe_markdown_writes_none_for_no_weight_average_and_explains_a_dash_only_where_one_is_shown():
    from types import SimpleNamespace

    from rfmap.paper.recipes import recipe_markdown, recipe_table

    class Model:
        def kwargs(self):
            return {"arch": "unet"}

    from rfmap.training.config import get_config

    config = {**get_config("deq2d-square", "ci").to_dict(), "lr": 2e-4, "ema": None, "val_sizes": [51]}
    meta = {"config": config, "steps": 10, "wall_time": 60.0,
            "final_metrics": {"mean": {"std_rho_map": 0.1, "raw_folded_fields": 0}}}
    md = recipe_markdown(recipe_table({"m": SimpleNamespace(meta=meta, model=Model())}))
    assert "| m | 2 × 10⁻⁴ | none | 10 | 1 |" in md
    assert "—" not in md and "not recorded" not in md
    bare = recipe_markdown(recipe_table({"m": SimpleNamespace(meta={"steps": 1}, model=Model())}))
    assert all("not recorded" in part for part in bare.split("\n\n**"))  # every part shows a dash


def test_preset_table_has_a_row_per_preset_with_its_schedule_and_time_limit():
    from rfmap.paper.recipes import preset_markdown
    from rfmap.paper.tables import rate_text
    from rfmap.training.config import PRESETS, get_config

    lines = preset_markdown("deq2d-square").splitlines()
    assert lines[0].startswith("| preset | steps | batch | N | peak lr |")
    assert [line.split(" | ")[0] for line in lines[2:]] == [f"| {p}" for p in PRESETS]
    paper = get_config("deq2d-square", "paper")
    row = lines[2 + PRESETS.index("paper")].split(" | ")
    assert row[1] == f"{paper.steps:,}" and row[4] == rate_text(paper.lr) and row[6] == paper.schedule
    assert row[7] == "none |"  # the paper's recipe has no time limit


def test_chain_table_has_a_row_per_run_with_what_its_command_set_and_what_it_ran():
    from rfmap.paper.recipes import chain_markdown

    runs = [{"run": 1, "steps": 2658, "step budget": 6000, "minutes": 50.01, "time limit (min)": 50.0,
             "peak lr": 5e-4},
            {"run": 2, "steps": 17000, "step budget": 17000, "minutes": 41.3, "time limit (min)": 70.0,
             "peak lr": 7e-5}]
    lines = chain_markdown(runs).splitlines()
    assert lines[0] == "| run | step budget | time limit | peak lr | steps run | minutes run |"
    assert lines[2] == "| 1 | 6,000 | 50 min | 5 × 10⁻⁴ | 2,658 | 50 |"
    assert lines[3] == "| 2 | 17,000 | 70 min | 7 × 10⁻⁵ | 17,000 | 41 |"
