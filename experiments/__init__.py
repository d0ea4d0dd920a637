"""Research experiments: scripts that print the tables a decision was taken on (a preset's
parameter, a modality's comparison, the calibration's hold-out; ``docs/evaluation.md``).

Run from the repository root, e.g. ``python -m experiments.size_cue``; each module's
docstring gives its options. They share :mod:`benchmarks.common`, never one another.
"""
