"""The benchmark code that the pytest suite (``python -m pytest benchmarks``) and the
``bench_*.py`` scripts share: one module per benchmark, each with ``run_*`` (one run, one result
row), ``record`` (merge the row into ``benchmarks/results/<name>.json`` and redraw the tables and
plots from all rows there) and the reference figures.

Scenes are run through the command line (``python -m fbmflow.cli run SCENE --level L --set ...``),
whose ``summary.json`` is the stable record of a run; see :mod:`fbmbench.common`.
"""
