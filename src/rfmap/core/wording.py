"""Counts in the package's messages, in the singular or the plural as the number asks: ``1 pass``, ``3 passes``.

Reports, warnings and errors count things ("2 folded elements", "1 region without data"); :func:`counted` writes
the number and the noun that agrees with it, so that no message reads "pass(es)".  :func:`of_count` writes a part of
a whole as a sentence says it: ``all 4 densities``, ``none of the 4``, ``3 of 4``; it never writes ``4 of 4`` or
``0 of 4``.  A tally in parentheses after a word is a score, not a phrase, and is written ``k of n`` whatever ``k``
is: the verdict of a paper table counts its met (case, metric) pairs so, as in ``reproduced (3 of 3)``
(:func:`rfmap.paper.verdicts.qualified_verdict`).
:func:`power_of_ten` and :func:`format_sig` write numbers without e-notation (``2.6 × 10⁻⁵``), for every layer of
the package (:mod:`rfmap.paper.tables` offers them too).
"""
from __future__ import annotations

import numpy as np

__all__ = ["counted", "of_count", "of_counts", "at_values", "power_of_ten", "format_sig"]

#: plurals that do not add "s" or "es"
_IRREGULAR = {"vertex": "vertices", "matrix": "matrices"}
#: words that end the noun of a phrase: "pair of regions", "region without data"
_PREPOSITIONS = {"of", "without", "with", "in", "under", "on", "per", "from", "to"}


def _plural(word: str) -> str:
    if word in _IRREGULAR:
        return _IRREGULAR[word]
    if len(word) > 1 and word.endswith("y") and word[-2] not in "aeiou":  # density, boundary
        return word[:-1] + "ies"
    return word + ("es" if word.endswith(("s", "x", "z", "ch", "sh")) else "s")


def counted(n: int, noun: str, plural: str | None = None) -> str:
    """``n`` and ``noun`` in the number that agrees with it: ``counted(1, "pass")`` is ``"1 pass"``,
    ``counted(3, "pass")`` is ``"3 passes"``, ``counted(2, "folded element")`` is ``"2 folded elements"``.

    Parameters
    ----------
    n : int
    noun : str
        The singular.  In a phrase the noun is the last word before a preposition (of, without, with, in, under,
        on, per, from, to), or the last word: ``"region without data"`` becomes ``"regions without data"``.
    plural : str, optional
        The plural of the whole phrase, where that rule is wrong.
    """
    n = int(n)
    if n == 1:
        return f"1 {noun}"
    if plural is None:
        words = noun.split(" ")
        k = next((i - 1 for i, w in enumerate(words) if i and w in _PREPOSITIONS), len(words) - 1)
        words[k] = _plural(words[k])
        plural = " ".join(words)
    return f"{n} {plural}"


def of_count(k: int, n: int, noun: str = "", plural: str | None = None) -> str:
    """``k`` of ``n`` things as a sentence says it: ``"3 of 4 densities"``, but ``"all 4 densities"`` where
    ``k == n``, ``"none of the 4 densities"`` where ``k == 0``, and ``"both"`` / ``"neither of the 2"`` / ``"the
    one"`` for wholes of one or two.  Without ``noun`` the bare count (``"all 4"``, ``"none of the 4"``); the noun is
    inflected as :func:`counted` does (``plural`` where that rule is wrong).

    Examples
    --------
    >>> of_count(4, 4, "density"), of_count(0, 4), of_count(3, 4, "side")
    ('all 4 densities', 'none of the 4', '3 of 4 sides')
    """
    k, n = int(k), int(n)
    if not 0 <= k <= n:
        raise ValueError(f"a part of a whole needs 0 <= k <= n, got k={k}, n={n}")
    nouns = counted(n, noun, plural).split(" ", 1)[1] if noun else ""
    tail = f" {nouns}" if nouns else ""
    if n == 1:
        return f"the one{tail}" if k == 1 else f"not the one{tail}"
    if n == 2 and k == 2:
        return f"both{tail}"
    if n == 2 and k == 0:
        return f"neither of the 2{tail}"
    if k == n:
        return f"all {n}{tail}"
    if k == 0:
        return f"none of the {n}{tail}"
    return f"{k} of {n}{tail}"


def of_counts(parts, nouns) -> str:
    """Several parts of wholes in one phrase, without repeating a count that says nothing: ``parts`` are ``(k, n)``
    pairs and ``nouns`` the singular noun of each whole (with its qualifier: ``"density with the cube boundary"``).
    Where every part is whole the phrase is ``"every one of them (...)"`` with the wholes counted, where none holds
    ``"none of them (...)"``; otherwise each part through :func:`of_count`, joined by commas and "and".

    Examples
    --------
    >>> of_counts([(4, 4), (4, 4), (4, 4)], ["density", "density", "side"])
    'every one of them (4 densities, 4 densities and 4 sides)'
    >>> of_counts([(1, 3), (0, 4)], ["density", "side"])
    '1 of 3 densities and none of the 4 sides'
    """
    parts = [(int(k), int(n)) for k, n in parts]
    nouns = list(nouns)
    if len(parts) != len(nouns):
        raise ValueError("one noun per part")

    def join(items):
        return items[0] if len(items) == 1 else ", ".join(items[:-1]) + " and " + items[-1]

    wholes = join([counted(n, noun) for (_, n), noun in zip(parts, nouns)])
    if all(k == n for k, n in parts):
        return f"every one of them ({wholes})"
    if all(k == 0 for k, _ in parts):
        return f"none of them ({wholes})"
    return join([of_count(k, n, noun) for (k, n), noun in zip(parts, nouns)])


def at_values(hits, total: int, name: str = "N", noun: str = "side") -> str:
    """Where something holds, by the values themselves rather than by a count: ``hits`` are the values at which it
    holds (grid sides, say) out of ``total`` values tried.

    Examples
    --------
    >>> at_values([64], 4), at_values([32, 64], 4), at_values([32, 51, 64], 4)
    ('at N = 64 only', 'at N = 32 and 64', 'at N = 32, 51 and 64')
    >>> at_values([], 4), at_values([32, 51, 128, 256], 4)
    ('at no side', 'at every side')
    """
    hits = [str(v) for v in hits]
    if not hits:
        return f"at no {noun}"
    if len(hits) == int(total):
        return f"at every {noun}"
    if len(hits) == 1:
        return f"at {name} = {hits[0]} only"
    return f"at {name} = " + ", ".join(hits[:-1]) + " and " + hits[-1]


_SUPERSCRIPT = str.maketrans("-0123456789", "⁻⁰¹²³⁴⁵⁶⁷⁸⁹")


def power_of_ten(v: float, digits: int = 3) -> str:
    """``v`` to ``digits`` significant digits as a power of ten in Unicode (no e-notation, safe in HTML and
    inside a sentence of the book): ``power_of_ten(2.5716e-05, 2)`` is ``"2.6 × 10⁻⁵"`` and ``power_of_ten(6e-06,
    1)`` is ``"6 × 10⁻⁶"``."""
    mantissa, exponent = f"{float(v):.{max(digits, 1) - 1}e}".split("e")
    return f"{mantissa} × 10{str(int(exponent)).translate(_SUPERSCRIPT)}"


def format_sig(v, digits: int = 3) -> str:
    """A number for a headline table: ``digits`` significant digits, in scientific notation (``3.81 × 10⁻⁵``) when
    its magnitude is below 10⁻³ or at least 10⁵; integers exactly; ``None`` or NaN as an em dash."""
    if v is None:
        return "—"
    if isinstance(v, (int, np.integer)) and not isinstance(v, (bool, np.bool_)):
        return str(int(v))
    v = float(v)
    if not np.isfinite(v):
        return "—"
    if v != 0 and not 1e-3 <= abs(v) < 1e5:
        return power_of_ten(v, digits)
    rounded = float(f"{v:.{digits}g}")
    if abs(rounded) >= 10 ** digits:  # 12,345 to three digits: 12,300, never 1.23e+04
        return f"{rounded:,.0f}"
    return f"{v:.{digits}g}"
