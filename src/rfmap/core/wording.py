"""Counts in the package's messages, in the singular or the plural as the number asks: ``1 pass``, ``3 passes``.

Reports, warnings and errors count things ("2 folded elements", "1 region without data"); :func:`counted` writes
the number and the noun that agrees with it, so that no message reads "pass(es)".
"""
from __future__ import annotations

__all__ = ["counted"]

#: plurals that do not add "s" or "es"
_IRREGULAR = {"vertex": "vertices", "matrix": "matrices"}
#: words that end the noun of a phrase: "pair of regions", "region without data"
_PREPOSITIONS = {"of", "without", "with", "in", "under", "on", "per", "from", "to"}


def _plural(word: str) -> str:
    if word in _IRREGULAR:
        return _IRREGULAR[word]
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
