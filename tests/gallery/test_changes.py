"""A gallery's searches against the changes the collector makes: a shape the database
already calls ready is found, even by a search that starts while its round is still
bringing the index along."""

from __future__ import annotations

import threading
import time
from concurrent.futures import ThreadPoolExecutor

from app.gallery.service import Gallery, Shape
from app.metrics import Metrics
from worker.engine.presets import DEFAULT_PRESET, get_preset


def test_a_search_during_a_change_in_flight_finds_the_shape_it_stores(tmp_path, verified_wholes):
    lock = threading.RLock()
    gallery = Gallery(
        (1, "default"),
        get_preset(DEFAULT_PRESET),
        tmp_path,
        refit_fraction=0.05,
        metrics=Metrics(),
        lock=lock,
    )
    gallery.load({}, lambda ids: [], followed=0)
    query, *others = verified_wholes
    for mesh_id, descriptor in enumerate(others, start=1):
        gallery.add(Shape(mesh_id, None, descriptor))
    new = len(others) + 1
    modalities = gallery.preset.scored_modalities
    with ThreadPoolExecutor(1) as pool:
        with lock:  # a collector round: its commit made the mesh ready, the index lags
            searching = pool.submit(gallery.search, query, 10, fusion=None, modalities=modalities)
            time.sleep(0.5)  # time enough for a search that does not wait to answer
            gallery.add(Shape(new, None, query))
        matches, _ = searching.result()
        scored = pool.submit(gallery.scores, query, [new]).result()
    assert new in [m.id for m in matches]
    assert new in scored
