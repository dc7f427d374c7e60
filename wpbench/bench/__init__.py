"""Speed and memory benchmarks; each module has ``run(...) -> dict`` (prints a table, optionally writes JSON) and ``main()``.

Timings are wall-clock on whatever CPU the run gets; on a shared machine they
are pessimistic. Compare numbers taken in the same run, not across runs.
"""
