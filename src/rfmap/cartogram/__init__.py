"""Cartograms of real regions, the GeoJSON application of the classical flow (torch-free: nothing here loads PyTorch
unless a surrogate is asked for).

:mod:`~rfmap.cartogram.resize` (:func:`~rfmap.cartogram.resize.cartogram`: regions resized by a value, pass after
pass), :mod:`~rfmap.cartogram.regions` (reading and checking regions, their density raster, real maps),
:mod:`~rfmap.cartogram.projection` (longitude/latitude to an equal-area plane), :mod:`~rfmap.cartogram.metrics` (area
errors and topology), :mod:`~rfmap.cartogram.data` (values from tables), :mod:`~rfmap.cartogram.output` (the written
GeoJSON), :mod:`~rfmap.cartogram.series` (time series), :mod:`~rfmap.cartogram.insets` (groups drawn in their own
frames), :mod:`~rfmap.cartogram.html` (interactive pages) and :mod:`~rfmap.cartogram.synthetic` (hard synthetic maps).
The command is ``rfmap cartogram`` (:mod:`rfmap.cli.cartogram`).
"""
