"""The gallery index: one owner (:class:`.service.Gallery`) for adds, removes, searches,
the lock, the labels, reconciliation with the enrolled shapes it is given at start and
the changes it is given after it, persistence and its metrics. Plain values in: no
database (:mod:`app.galleries` feeds it).

Inside: :mod:`.vectors` (exact vectors, running sigma), :mod:`.candidates` (candidate
transforms and faiss), :mod:`.index` (updates, refits, the certified search),
:mod:`.persistence` (files), :mod:`.pairs` (the labelled pairs' scores and the
calibration fitted on them), :mod:`.weights` (the fusion weights in use, learned,
pinned or the preset's).
"""
