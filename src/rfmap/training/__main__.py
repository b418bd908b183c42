"""``python -m rfmap.training`` (and ``torchrun ... -m rfmap.training``): the command line of training, as
``rfmap train`` (:func:`rfmap.training.cli.main`)."""
import sys

from .cli import main

if __name__ == "__main__":
    sys.exit(main())
