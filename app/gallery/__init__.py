"""The gallery index: one owner (:class:`.service.Gallery`) for adds, removes, searches,
the lock, reconciliation with the database at start and the change log after it,
persistence and its metrics.

Inside: :mod:`.vectors` (exact vectors, running sigma), :mod:`.candidates` (candidate
transforms and faiss), :mod:`.index` (updates, refits, the certified search),
:mod:`.persistence` (files), :mod:`.changes` (the log every API process follows).
"""
