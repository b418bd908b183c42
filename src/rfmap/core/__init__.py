"""The core below everything else: the metrics of a map, the result every map computation returns, fold checks of
meshes and surfaces, and where the network runs.

:mod:`~rfmap.core.geometry` (Beltrami coefficients, Jacobians and element measures of a piecewise-linear map),
:mod:`~rfmap.core.metrics` (the paper's measures of a map), :mod:`~rfmap.core.mesh` (grids and meshes),
:mod:`~rfmap.core.inputs` (checking and normalising inputs), :mod:`~rfmap.core.result`
(:class:`~rfmap.core.result.MapResult` and its exports), :mod:`~rfmap.core.folds` and :mod:`~rfmap.core.surface`
(folded elements, crossing boundaries) and :mod:`~rfmap.core.device` (CPU or GPU, threads).
"""
