"""Workflows: the orchestrators above the machinery (the layer just below the command line and the API).

``identify`` (Pareto front, Eq. 11 choice), ``identify_linear`` (three objectives), ``close_loop`` (residual ->
effect -> re-identify), ``trim_loop`` (trim-only flight tests), ``multistart`` and ``benchmark``. Those that write
a results folder share one :class:`~pyomo_heli.workflows.run_folder.RunFolder` (log, provenance, claim, lock,
point store, front table, progress). They import everything below them; nothing below imports them
(tests/test_import_layers.py).
"""
