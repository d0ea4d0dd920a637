"""Performance benchmarks: scripts that print tables (``docs/benchmarks.md`` cites them).

Run from the repository root, e.g. ``python -m benchmarks.descriptor``; each module's
docstring gives its options. :mod:`benchmarks.common` holds what they, the experiments
and the service tests share.
"""
