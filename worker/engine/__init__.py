"""The descriptor engine: Smeets et al. (2010)'s GDM/DDT modal representation as a pure
library (numpy arrays in, numpy arrays out; see docs/engine.md).

It imports only numpy, scipy, trimesh, tensorly and fast-simplification (checked by
tests/test_rooms.py). ``pipeline.describe_file`` is the entry point.
"""
