"""An index on disk: ``manifest.json``, ``arrays.npz`` and one faiss file per modality.

Written to a sibling temporary directory and renamed into place, so a crash
leaves either the old index or the new one. The database stays the source of
truth: an index that cannot be read is rebuilt from it (:mod:`.service`).

Every sample's parts profiles are not copied in: an index that keeps them in a file
(:class:`~.vectors.PartsRows`, beside the directory) records which slot of it each
shape has; the file only grows, so the rows a saved index refers to never change.
An index that keeps them in memory saves them in ``arrays.npz``.
"""

from __future__ import annotations

import json
import shutil
import time
from pathlib import Path
from typing import Any

import faiss
import numpy as np

from worker.engine.presets import Preset

from .candidates import CandidateTransform, searchable
from .index import GalleryIndex
from .vectors import ids_fingerprint
from .words import SampleWords

FORMAT_VERSION = 2  # 2: the parts' coarse rows and slots, the samples' inverted file


def save_index(index: GalleryIndex, directory: Path) -> None:
    """Write ``index`` atomically to ``directory`` (replacing it); the index is clean after."""
    with index.lock:
        if index.fits is None:
            index.refit()
        fits = index.fits
        assert fits is not None
        store = index.store
        n = store.n
        tmp = directory.with_name(directory.name + ".tmp")
        shutil.rmtree(tmp, ignore_errors=True)
        tmp.mkdir(parents=True)
        # Any: np.savez also takes a keyword allow_pickle, which the typed dict must not hide.
        arrays: dict[str, Any] = {"ids": store.ids[:n]}
        rows = store.rows
        if rows is not None:
            arrays["coarse"] = store.coarse[:n]
            if rows.path is None:  # in memory: the rows themselves, by position
                arrays["parts"] = store.parts_at(np.arange(n))
            else:
                rows.flush()
                arrays["slots"] = store.slots[:n]
        for m in index.modalities:
            fit = fits[m]
            arrays.update(
                {
                    f"{m}.vectors": store.vectors[m][:n],
                    f"{m}.shift": store.shift[m],
                    f"{m}.sum": store.sum[m],
                    f"{m}.sumsq": store.sumsq[m],
                    f"{m}.mu": fit.mu,
                    f"{m}.scale": fit.scale,
                    f"{m}.floor": fit.floor,
                    f"{m}.projection": fit.projection,
                    f"{m}.reduced": index.reduced[m][:n],
                }
            )
            faiss.write_index(fit.index, str(tmp / f"{m}.faiss"))
        if index.words is not None:
            arrays.update({f"words.{k}": v for k, v in index.words.arrays().items()})
        np.savez(tmp / "arrays.npz", **arrays)
        manifest = {
            "format": FORMAT_VERSION,
            "preset": index.preset.name,
            "preset_version": index.preset.version,
            "dims": index.dims,
            "comparisons": {m: fits[m].comparison for m in index.modalities},
            "parts_shape": store.parts_shape,
            "parts_file": None if rows is None or rows.path is None else rows.path.name,
            "parts_count": 0 if rows is None else rows.count,
            "size": n,
            "n_at_fit": index.n_at_fit,
            "changes_since_fit": index.changes_since_fit,
            "fingerprint": ids_fingerprint(store.ids[:n]),
            "saved_at": time.time(),
        }
        (tmp / "manifest.json").write_text(json.dumps(manifest, indent=1))
        old = directory.with_name(directory.name + ".old")
        shutil.rmtree(old, ignore_errors=True)
        if directory.exists():
            directory.rename(old)
        tmp.rename(directory)
        shutil.rmtree(old, ignore_errors=True)
        index.dirty = False


def load_index(directory: Path, preset: Preset, **options: Any) -> GalleryIndex:
    """Read an index written by :func:`save_index` (``options`` as for ``GalleryIndex``).

    Raises
    ------
    ValueError
        Missing, corrupt or made for another preset version; rebuild it then.
    """
    try:
        return _read(directory, preset, **options)
    except ValueError:
        raise
    except Exception as exc:  # corrupt files surface as many types
        raise ValueError(f"unreadable index: {exc}") from exc


def _read(directory: Path, preset: Preset, **options: Any) -> GalleryIndex:
    manifest = json.loads((directory / "manifest.json").read_text())
    if manifest.get("format") != FORMAT_VERSION or (
        manifest["preset"],
        manifest["preset_version"],
    ) != (preset.name, preset.version):
        raise ValueError("index made by another format or preset version")
    shape = manifest.get("parts_shape")
    parts_shape = None if shape is None else (int(shape[0]), int(shape[1]))
    parts_file = manifest.get("parts_file")
    path = None if parts_file is None else directory.parent / parts_file
    index = GalleryIndex(
        preset, manifest["dims"], parts_shape=parts_shape, parts_path=path, **options
    )
    rows = index.store.rows
    if path is not None and rows is not None:
        if path.stat().st_size < int(manifest["parts_count"]) * rows.row_bytes:
            raise ValueError("the parts file is shorter than the index refers to")
    with np.load(directory / "arrays.npz") as npz:
        arrays = {k: np.array(npz[k]) for k in npz.files}
    n = int(manifest["size"])
    ids = arrays["ids"].astype(np.int64)
    if len(ids) != n or ids_fingerprint(ids) != manifest["fingerprint"]:
        raise ValueError("index ids do not match its manifest")
    store = index.store
    store.ensure_capacity(n)
    store.ids[:n] = ids
    store.pos = {int(i): p for p, i in enumerate(ids)}
    store.n = n
    if store.rows is not None:
        store.coarse[:n] = arrays["coarse"]
        if path is None:
            for position in range(n):
                store.slots[position] = store.rows.append(arrays["parts"][position])
        else:
            store.rows.count = int(manifest["parts_count"])
            store.slots[:n] = arrays["slots"]
    fits = {}
    # Files written before the comparisons were recorded: the preset's D1 or D2 for all.
    saved = manifest.get("comparisons") or {m: preset.dissimilarity for m in index.modalities}
    for m in index.modalities:
        store.vectors[m][:n] = arrays[f"{m}.vectors"]
        store.shift[m] = arrays[f"{m}.shift"]
        store.sum[m] = arrays[f"{m}.sum"]
        store.sumsq[m] = arrays[f"{m}.sumsq"]
        reduced = arrays[f"{m}.reduced"].astype(np.float32)
        index.reduced[m] = np.empty((store.capacity, reduced.shape[1]), np.float32)
        index.reduced[m][:n] = reduced
        faiss_index = searchable(faiss.read_index(str(directory / f"{m}.faiss")))
        if faiss_index.ntotal != n:
            raise ValueError(f"faiss index of {m} has {faiss_index.ntotal} rows, not {n}")
        fits[m] = CandidateTransform(
            comparison=saved[m],
            mu=arrays[f"{m}.mu"],
            scale=arrays[f"{m}.scale"],
            floor=arrays[f"{m}.floor"],
            projection=arrays[f"{m}.projection"],
            index=faiss_index,
        )
    index.fits = fits
    saved_words = {k.removeprefix("words."): v for k, v in arrays.items() if k.startswith("words.")}
    if saved_words:
        index.words = SampleWords.from_arrays(saved_words)
    index.n_at_fit = int(manifest["n_at_fit"])
    index.changes_since_fit = int(manifest["changes_since_fit"])
    index.dirty = False
    changed = [m for m in index.modalities if saved[m] != preset.comparison(m)]
    if changed:  # saved under another fusion's comparisons
        index.refit(changed)
    return index
