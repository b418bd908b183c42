r"""The code of the book's chapters and tables, one module per kind of study, built on the library below it.

Each module is named by what it shows:

- :mod:`~rfmap.paper.tables`: the table formatter, the paper's published tables and the numbers of the book's text
  as words;
- :mod:`~rfmap.paper.verdicts`: the verdict word of a paper table or figure, and whether a test input is the
  paper's;
- :mod:`~rfmap.paper.comparison`: each paper table as a four-way comparison (the paper, the paper's method run
  natively, the delivered map and the flow solver) with one criterion; the chapters' tables and the
  scoreboard;
- :mod:`~rfmap.paper.ablations`: weight refinement against :math:`\alpha = 1`;
- :mod:`~rfmap.paper.reproduce`: the per-map values, and the tables of ``rfmap reproduce``: the paper's published
  rows beside the network's and the diffusion DEM's, without the book's four-way comparison;
- :mod:`~rfmap.paper.generalization`: unseen random fields, distortion, displacement demand;
- :mod:`~rfmap.paper.recipes`: how the models were trained;
- :mod:`~rfmap.paper.benchmarks`: classical, neural and hybrid maps side by side;
- :mod:`~rfmap.paper.flow_studies`: studies of the flow-based solver;
- :mod:`~rfmap.paper.design`: the design decisions page (documented on the page of the book's internals);
- :mod:`~rfmap.paper.cartograms`: the cartogram chapter's tables;
- :mod:`~rfmap.paper.compare`: two surrogates of one task side by side (the U-Net against the Fourier neural
  operator);
- :mod:`~rfmap.paper.folding`: the first hard field that folds a surrogate's raw map, documented with the repair
  functions that it serves.
"""
