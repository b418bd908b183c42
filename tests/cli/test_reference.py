"""The reference page of the command line lists every sub-command's options, read from the parsers."""
import importlib.util
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
