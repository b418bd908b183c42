"""The options of every ``rfmap`` sub-command as Markdown, read from the parsers themselves, so that the reference
page of the command line lists what ``rfmap <sub-command> --help`` prints and cannot fall behind it.

The Markdown renders as the terminal prints the help: the options that a help text names are set in code, and
characters that Markdown would read as markup are escaped."""
# an option named in a help text (--resume) is set in code, where MyST's typographer does not turn its two hyphens
# into a dash; a | is escaped so that it stays inside its table cell
from __future__ import annotations

import argparse
import re

__all__ = ["subcommand_parsers", "options_markdown"]


def subcommand_parsers() -> dict[str, argparse.ArgumentParser]:
    """The parser of each sub-command of ``rfmap``, in the order of ``rfmap --help``, with all its arguments."""
    from .commands import build_parser

    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    out = {}
    for name, p in sub.choices.items():
        p.format_usage()  # a parser filled on first use (rfmap train) gets its arguments now
        out[name] = p
    return out


def _names(action: argparse.Action) -> str:
    """The first cell of an argument's row: its name, or each option string with its value as ``--help`` writes
    it (``--n-range LO HI``, ``--init MODEL|FILE``), in code, a ``|`` escaped so that it does not end the cell."""
    if not action.option_strings:
        return f"`{action.metavar or action.dest}`"
    if action.nargs == 0:
        value = ""
    else:
        metavar = action.metavar or (action.dest.upper() if not action.choices else
                                     "{" + ",".join(map(str, action.choices)) + "}")
        if isinstance(metavar, tuple):
            metavar = " ".join(metavar)
        value = f" {metavar}" if action.nargs is None else f" {metavar} ..." if action.nargs in ("+", "*") else \
            f" [{metavar}]" if action.nargs == "?" else f" {metavar}"
    return ", ".join(f"`{o}{value}`".replace("|", "\\|") for o in action.option_strings)


#: characters of a help text that Markdown (or MyST's dollar math) would read as markup
_MARKUP = str.maketrans({c: "\\" + c for c in "\\`*_$<>[]|"})


#: an option named in a help text (``--resume``, ``--device``), not part of a longer word, or a dotted Python name
#: (``rfmap.tasks.kinds``, ``Surrogate.map(native=True)``; every part at least two characters, so not "e.g.", and
#: not part of a path)
_OPTION = re.compile(r"(?<![\w-])--[a-z][a-z0-9-]*(?![\w-])"
                     r"|(?<![\w./-])[A-Za-z_]\w+(?:\.[A-Za-z_]\w+)+(?:\([^()\s]*\))?(?![\w/-])")


def _cell(text: str) -> str:
    """A help text as one Markdown table cell, its markup characters escaped so that it reads as written and the
    options and dotted names it names set in code."""
    parts = _OPTION.split(" ".join(text.split()))
    names = _OPTION.findall(" ".join(text.split()))
    out = parts[0].translate(_MARKUP)
    for name, rest in zip(names, parts[1:]):
        out += f"`{name}`" + rest.translate(_MARKUP)
    return out


def _description(action: argparse.Action) -> str:
    text = _cell(action.help or "")
    if action.required and action.option_strings:
        text = "required; " + text if text else "required"
    if action.choices and action.option_strings and action.metavar:
        text += f" One of {', '.join(f'`{c}`' for c in action.choices)}."
    if action.default not in (None, False, argparse.SUPPRESS, []) and action.nargs != 0 \
            and "default" not in text:
        text += f" Default: `{action.default}`."
    return text.strip() or "—"


def options_markdown(level: int = 3) -> str:
    """One section per sub-command (a heading of ``level``, its one-line purpose, its usage and a table of its
    arguments and options with their help, defaults and choices), in the order of ``rfmap --help``.

    Examples
    --------
    >>> text = options_markdown()
    >>> "rfmap map" in text and "--no-repair" in text
    True
    """
    from .commands import build_parser

    helps = {a.dest: a.help for a in
             next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))._choices_actions}
    parts = []
    for name, p in subcommand_parsers().items():
        usage = " ".join(p.format_usage().replace("usage: ", "").split())
        purpose = _cell(helps.get(name) or p.description or "")
        rows = ["| argument or option | meaning |", "|---|---|"]
        rows += [f"| {_names(a)} | {_description(a)} |" for a in p._actions
                 if not isinstance(a, argparse._HelpAction)]
        parts.append(f"{'#' * level} `rfmap {name}`\n\n{purpose[:1].upper() + purpose[1:]}.\n\n"
                     f"```text\n{_wrap(usage)}\n```\n\n" + "\n".join(rows))
    return "\n\n".join(parts) + "\n"


def _tokens(usage: str) -> list[str]:
    """The words of a usage line, an optional or grouped argument (``[--n N]``, ``(--field FIELD | ...)``) as one."""
    out, depth = [""], 0
    for ch in usage:
        if ch == " " and depth == 0:
            out.append("")
            continue
        depth += (ch in "[(") - (ch in "])")
        out[-1] += ch
    return [t for t in out if t]


def _wrap(usage: str, width: int = 76) -> str:
    """A usage line broken between arguments, continued lines indented, so that no line is longer than ``width``
    where an argument fits on a line."""
    lines: list[str] = []
    for word in _tokens(usage):
        if lines and len(lines[-1]) + 1 + len(word) <= width:
            lines[-1] += " " + word
        else:
            lines.append(("    " if lines else "") + word)
    return "\n".join(lines)
