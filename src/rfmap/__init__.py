"""rfmap: resolution-free neural surrogates for geometric mapping."""
__version__ = "0.1.0"
