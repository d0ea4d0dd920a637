"""The job runner: the Huey queue the workers consume, and the limits a job runs under.

``settings`` is light (pydantic-settings only) so the service can build its
settings on it without loading Huey or the engine; ``queue`` and ``limits`` are
what ``python -m worker`` runs.
"""
