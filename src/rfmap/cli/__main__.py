"""``python -m rfmap.cli``: the ``rfmap`` program (:func:`rfmap.cli.commands.entry`)."""
from .commands import entry

if __name__ == "__main__":
    entry()
