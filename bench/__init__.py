"""Benchmarks of the feedrate scheduler against peer libraries (toppra, copp-py, Ruckig).

Run one with ``.venv/bin/python -m bench.<name>`` or all with ``python -m bench.run_all``.
Every script prints a JSON dict on its last stdout line.
"""
