"""The reference page of the command line lists every sub-command's options, read from the parsers."""
import importlib.util
import re
from pathlib import Path

from rfmap.cli.reference import options_markdown, subcommand_parsers

ROOT = Path(__file__).resolve().parents[2]


def test_every_sub_command_and_option_is_listed():
    text = options_markdown()
    for name, parser in subcommand_parsers().items():
        assert f"### `rfmap {name}`" in text
        for action in parser._actions:
            for option in action.option_strings:
                if option not in ("-h", "--help"):
                    assert f"`{option}" in text, (name, option)
    assert "`--no-repair` | return the raw network map" in text
    assert "| `--out OUT` | required; output .npz |" in text


def test_usage_lines_fit_a_code_box():
    text = options_markdown()
    blocks = text.split("```text\n")[1:]
    assert blocks and all(len(line) <= 79 for b in blocks for line in b.split("```")[0].splitlines())


def test_the_cli_page_is_up_to_date_and_rebuilt_by_make_pages():
    spec = importlib.util.spec_from_file_location("make_cli_md", ROOT / "scripts" / "make_cli_md.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    assert module.main(["--check"]) == 0, "book/api/cli.md is stale: run python scripts/make_cli_md.py"
    assert "$(BIN)/python scripts/make_cli_md.py" in (ROOT / "Makefile").read_text(encoding="utf-8")


def test_every_table_row_has_two_cells_and_options_render_as_typed():
    """A ``|`` in a metavar (``--init MODEL|FILE``) is escaped, so it does not split its cell, and an option named in
    a help text is in code, where the book's typographer does not turn ``--`` into a dash."""
    text = options_markdown()
    rows = [line for line in text.splitlines() if line.startswith("| ")]
    assert rows and all(len(re.split(r"(?<!\\)\|", row)) == 4 for row in rows), \
        [row for row in rows if len(re.split(r"(?<!\\)\|", row)) != 4]
    assert "| `--init MODEL\\|FILE` |" in text and "| `--n-range LO HI` |" in text
    prose = re.sub(r"```text\n.*?```|\|---\|---\|", "", text, flags=re.S)
    assert "--" not in re.sub(r"`[^`]*`", "", prose)
    assert all(not row.endswith("| — |") for row in rows), [row for row in rows if row.endswith("| — |")]


def test_the_page_names_every_built_in_field():
    """The prose of book/api/cli.md lists the names ``--field`` accepts: every built-in field, none that is not."""
    import re

    from rfmap.fields.paper import field_names

    text = (ROOT / "book" / "api" / "cli.md").read_text(encoding="utf-8")
    para = text[text.index("`--field` takes the name of a built-in field"):]
    para = para[:para.index("\n\n")]
    listed = re.findall(r"(?<!\})`([A-Za-z0-9-]+)`", para)  # not the page name of a {doc} link
    names = [n for n in listed if not n.startswith("--")]
    assert sorted(names) == sorted(field_names())
