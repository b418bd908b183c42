"""The paper layer: what the book shows, built on the library below it.

Each module is named by what it shows: :mod:`~rfmap.paper.tables` (the table formatter, the paper's published
tables and the glue of numbers into the text), :mod:`~rfmap.paper.reproduce` (the paper's tables, ``rfmap
reproduce``), :mod:`~rfmap.paper.generalization` (unseen random fields, distortion, displacement demand),
:mod:`~rfmap.paper.recipes` (how the models were trained), :mod:`~rfmap.paper.benchmarks` (classical, neural and
hybrid maps side by side), :mod:`~rfmap.paper.flow_studies` (studies of the flow-based solver),
:mod:`~rfmap.paper.cartograms` (the cartogram chapter's tables) and :mod:`~rfmap.paper.design` (the design decisions
page).  Nothing in the library imports this layer.
"""
