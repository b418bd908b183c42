"""The design record (src/rfmap/data/design.json), its page (book/design.md) and the script that measures it again
(benchmarks/design.py)."""
from __future__ import annotations

import importlib.util
import re
import subprocess
import sys
from pathlib import Path

import pytest

from rfmap.paper.design import (DESIGN_PATH, current_value, display_name, finding, kept_text, load_decisions,
                                plain_numbers, readable_value, record, remeasure_command, stale_values, to_markdown,
                                _label, _sentence)

ROOT = Path(__file__).resolve().parent.parent


def _load(path: Path, name: str):
    spec = importlib.util.spec_from_file_location(name, path)
    mod = importlib.util.module_from_spec(spec)
    sys.modules[name] = mod  # a dataclass of the module looks its module up
    spec.loader.exec_module(mod)
    return mod


def _cases() -> dict:
    return _load(ROOT / "benchmarks" / "design.py", "design_benchmark").CASES


def test_design_page_is_up_to_date_and_in_the_toc():
    assert (ROOT / "book" / "design.md").read_text(encoding="utf-8") == to_markdown(), \
        "book/design.md is stale: run python scripts/make_design_md.py"
    assert "- file: book/design" in (ROOT / "_toc.yml").read_text(encoding="utf-8")
    assert _load(ROOT / "scripts" / "make_design_md.py", "make_design_md").main(["--check"]) == 0


def test_design_values_are_those_in_the_code():
    """Every constant recorded in design.json holds the recorded value in the code (a changed constant needs new
    measurements)."""
    decisions = load_decisions()
    assert len({d["constant"] for d in decisions}) == len(decisions)
    for d in decisions:
        for key in ("module", "value", "what", "criterion", "benchmark"):
            assert str(d.get(key, "")).strip(), (d["constant"], key)
    assert sum(current_value(d) is not None for d in decisions) >= 15
    assert stale_values() == []
    changed = [{**decisions[0], "value": "(2, 3)"}]
    assert stale_values(changed) == [(decisions[0]["constant"], "(2, 3)", decisions[0]["value"])]


def test_every_decision_is_re_measurable_or_a_dated_record():
    """A decision either names a case of benchmarks/design.py, whose last run's rows, data, date, code version and
    machine are stored, or is a historical record with the commits that set the value and entered its numbers."""
    cases = _cases()
    keys = [d["remeasure"] for d in load_decisions() if d.get("remeasure")]
    assert sorted(keys) == sorted(cases), "every case of benchmarks/design.py measures exactly one decision"
    for d in load_decisions():
        if d.get("remeasure"):
            assert d["benchmark"] == "benchmarks/design.py" and "recorded" not in d, d["constant"]
            assert remeasure_command(d) == f"python benchmarks/design.py --only {d['remeasure']}"
            assert d.get("results") and d.get("data"), f"{d['constant']}: run benchmarks/design.py --record"
            assert {"date", "code", "machine"} <= set(d.get("measured", {})), d["constant"]
            assert d["measured"]["code"].startswith("rfmap ")
        else:
            entered = d.get("recorded", {}).get("entered", {})
            assert entered.get("commit") and entered.get("date"), d["constant"]
            assert remeasure_command(d) is None


def test_recorded_commits_are_in_the_history():
    git = ROOT / ".git"
    if not git.exists():
        pytest.skip("not a git checkout")
    commits = {e["commit"] for d in load_decisions() for e in d.get("recorded", {}).values()}
    for sha in sorted(commits):
        out = subprocess.run(["git", "-C", str(ROOT), "cat-file", "-e", f"{sha}^{{commit}}"], capture_output=True)
        assert out.returncode == 0, f"design.json names commit {sha}, which the history does not hold"


def test_the_page_says_how_to_re_measure_and_what_is_historical():
    page = to_markdown()
    for d in load_decisions():
        if d.get("remeasure"):
            assert f"`{remeasure_command(d)}`" in page
    records = [d for d in load_decisions() if not d.get("remeasure")]
    assert page.count(", not re-measured.**") == len(records)
    for d in records:
        date = ((d.get("recorded") or {}).get("entered") or {}).get("date")
        if date:
            assert f"**Record of {date}, not re-measured.**" in page
    # what a record means is said once, not in every section
    assert page.count("code has changed since") == 1


def test_headings_and_the_table_of_decisions_show_no_python_reprs():
    """A section's heading is the constant's name; its value appears in the body, in words (no dict or tuple repr,
    no quoted strings, no e-notation)."""
    page = to_markdown()
    headings = [line for line in page.splitlines() if line.startswith("#")]
    glance = page[page.index("## At a glance"):page.index("## ", page.index("## At a glance") + 3)]
    for text in headings + glance.splitlines():
        assert " = " not in text and "{" not in text and not re.search(r"'\w+'|\de-\d", text), text
    for d in load_decisions():
        assert f"### {display_name(d)}\n\n**Value:** {readable_value(d)}" in page
    by = {d["constant"]: d for d in load_decisions()}
    assert readable_value(by["SMOOTH_PASSES"]).startswith("2D, square boundary: 2; 3D, square boundary: 8")
    assert readable_value(by["RTOL"]) == "2D: 0.2; 3D: 0.4" and readable_value(by["HYBRID_POLISH"]) == "10⁻⁹"
    assert "| maps scored (lower is better) | step 7,000 | step 1,000 |" in page, "a decision's own column heads"
    assert "| blend | mean Std(ρ̃_map) over the diffusion solver's" in page, "two heads of a one-sided table"
    assert page.rstrip().endswith("```") and page.index("## Measuring again") > page.index("## Training"), \
        "how to measure again closes the page, after the decisions"
    assert display_name(by["_HARD2 (p_hard)"]) == "Share of hard fields in 2D training"
    assert "**Value:** 0.3 (training config key `density_field.p_hard` of " in page
    assert "._HARD" not in page and "._FOLD" not in page, "a private name on the page"
    assert display_name(by["RTOL"]) == "Step size of the flow solver (`RTOL`)"
    assert not [h for h in headings if h.startswith("### `")], "a heading that is only a code name"
    assert not [h for h in headings if "`_" in h], "a private name as a heading"
    assert display_name(by["validation score"]) == "Choosing a training run's checkpoint"
    # every decision has a plain title; a public constant follows it in backticks, as the reader would type it
    for d in load_decisions():
        assert d.get("title") and display_name(d).startswith(d["title"]), d["constant"]
        if d.get("attribute") and not d["constant"].startswith("_"):
            assert display_name(d).endswith(f"(`{d['attribute']}`)"), d["constant"]


#: decisions whose recorded numbers contradict the chosen value
CONTRADICTED = ["one grid_sample batch entry per thread", "SCAN_POINTS", "_FOLD_HARD3 (fold weight)",
                "_HARD2 (p_hard)", "_HARD3 (p_hard)", "_FOLD_HARD (fold weight)", "HYBRID_POLISH",
                "validation score"]


def test_findings_say_where_the_numbers_do_not_support_the_value():
    """A finding is shown in its section with the rows it rests on and its own account of what is known and what
    was not measured (no stock reason shared between decisions), and the overview says plainly that the numbers do
    not support the value; the page says once that timings taken under load can mislead, without load averages or
    commits in its text."""
    page = to_markdown()
    assert page.count("can come from that load rather than from the setting") == 1
    assert "load average" not in page and "commit" not in page
    by = {d["constant"]: d for d in load_decisions()}
    own = [name for name in CONTRADICTED if by[name]["finding"].get("lead")]  # a narrower gap, in its own words
    assert page.count("**Not supported by the") == len(CONTRADICTED) - len(own)
    assert {c for c, d in by.items() if d.get("finding")} == set(CONTRADICTED)
    for name in CONTRADICTED:
        d = by[name]
        text = "\n".join(finding(d))
        lead = d["finding"].get("lead")
        assert text in page and (f"**{lead}.**" if lead else "does not support the choice") in text
        for case in d["finding"]["rows"]:
            row = next(r for r in d["results"] if r["case"] == case)
            assert case in text and all(plain_numbers(str(row[k])) in text for k in ("chosen", "alternative")
                                        if row.get(k))
        short = d["finding"].get("short")
        assert kept_text(d) in page and kept_text(d).startswith(f"**{short}." if short else "**Not supported by the")
        assert d["finding"]["why_kept"].rstrip(".") in text and d["kept"] in kept_text(d)
    reasons = [by[name]["finding"]["why_kept"] for name in CONTRADICTED] + [by[name]["kept"] for name in CONTRADICTED]
    assert len(set(reasons)) == len(reasons), "two decisions share a reason"
    for stock in ("does not settle the choice", "idle machine can", "The value is kept because"):
        assert stock not in page, stock
    broken = {**by["BATCH_POINTS"], "finding": {"text": "x", "rows": ["no such case"], "why_kept": "y"}}
    with pytest.raises(KeyError):
        finding(broken)
    with pytest.raises(KeyError):  # a finding without its own reason is refused, not given a stock one
        finding({**by["BATCH_POINTS"], "finding": {"text": "x", "rows": []}})


def test_every_decision_says_in_plain_words_what_it_is_for_and_why_it_stays():
    """The table of decisions: what each controls, what the measurement showed and why the value is kept (or that
    the numbers do not support it), in words; numbers of the record written as powers of ten, not e-notation."""
    page = to_markdown()
    glance = page[page.index("## At a glance"):page.index("\n## ", page.index("## At a glance"))]
    assert glance.count("\n- [") == len(load_decisions())
    for d in load_decisions():  # each overview entry links to its section by the section's label
        assert f"- [{display_name(d)}]({_label(d)}): {readable_value(d)}." in glance, d["constant"]
        assert f"({_label(d)})=\n### {display_name(d)}\n" in page, d["constant"]
    # a section gives its criterion outside the collapsed block, not the overview's purpose or outcome again
    for d in load_decisions():
        section = page[page.index(f"### {display_name(d)}\n"):]
        head = section[:section.index("::::{dropdown}")]
        assert f"**Criterion:** {d['criterion']}." in head and "**Outcome:**" not in head, d["constant"]
        assert page.count(_sentence(d["outcome"])) == 1, d["constant"]
        assert d["purpose"] not in head, d["constant"]
        if d.get("alternatives_per_case"):
            assert "**Tried per case:** see the table." in section[:section.index("\n::::\n")]
    for d in load_decisions():
        assert d.get("purpose") and d.get("outcome") and d.get("kept"), d["constant"]
        words = re.sub(r"\b[23]D\b|chapter \d+|counted as 1", "", d["purpose"] + d["outcome"] + d.get("kept", ""))
        assert not re.search(r"\d", words), (d["constant"], words)  # measured numbers come from the record
    assert not re.search(r"\d\.?\d*e-\d", page)
    assert plain_numbers("at most 8.9e-16, about 1e-7") == "at most 8.9 × 10⁻¹⁶, about 10⁻⁷"


def test_design_record_updates_one_entry(tmp_path):
    path = tmp_path / "design.json"
    path.write_text(DESIGN_PATH.read_text(encoding="utf-8"), encoding="utf-8")
    rows = [{"case": "3D, N = 48", "chosen": "0.70 s", "alternative": "1.10 s"}]
    assert record("MARGIN", path=path, results=rows, data="x")["results"] == rows
    after = {d["constant"]: d for d in load_decisions(path)}
    assert after["MARGIN"]["results"] == rows and after["RTOL"] == {d["constant"]: d for d in load_decisions()}["RTOL"]
    # a decision that is not a constant is found by its case name
    assert record("velocity-table-float32", path=path, results=rows)["constant"] == "velocity table in float32"
    with pytest.raises(KeyError):
        record("NO_SUCH_CONSTANT", path=path, value="1")


def test_design_benchmark_measures_and_records(tmp_path):
    """benchmarks/design.py at the smallest size: one row per 3D test density and decision, stored with --record."""
    path = tmp_path / "design.json"
    path.write_text(DESIGN_PATH.read_text(encoding="utf-8"), encoding="utf-8")
    out = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "design.py"), "--n", "9", "--repeat", "1",
                          "--only", "RTOL", "MARGIN", "--record", "--out", str(path)],
                         capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr[-2000:]
    rows = [line for line in out.stdout.splitlines() if line.startswith("| ") and "3D N = 9" in line]
    assert len(rows) == 8
    stored = {d["constant"]: d for d in load_decisions(path)}
    assert len(stored["RTOL"]["results"]) == 8 and len(stored["MARGIN"]["results"]) == 4  # RTOL: 3D and 2D
    for decision in ("RTOL", "MARGIN"):
        assert "N = 9" in stored[decision]["data"] and stored[decision]["measured"]["code"].startswith("rfmap ")
    assert load_decisions() != load_decisions(path)  # the package's record is untouched


#: the cases cheap enough for the test suite at their smallest size (the others load the shipped networks)
SMALL = ["WALK_FILL", "RESIDUAL_ITERATIONS", "element-measures-float32", "velocity-table-float32",
         "grid-sample-per-thread", "fno-size"]


def test_design_benchmark_cases_print_their_tables():
    out = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "design.py"), "--n", "9", "--repeat", "1",
                          "--only", *SMALL], capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr[-2000:]
    for name in SMALL:
        assert f"### {name}\n\n| case | chosen | alternative |" in out.stdout, name
    assert "rasters differ by at most" in out.stdout
    listed = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "design.py"), "--list"], capture_output=True,
                            text=True, timeout=120).stdout
    assert all(name in listed for name in _cases())
