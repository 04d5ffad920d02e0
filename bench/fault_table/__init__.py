"""The fault table of ``bench_faults.py``: the harness that flies and measures a row, the rows, the report."""
