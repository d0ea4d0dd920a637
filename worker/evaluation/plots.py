"""CMC and ROC plots of an evaluation report, like Fig. 5 of Smeets et al. (2010).

Uses matplotlib's object API with the Agg canvas, so no display and no global
backend state are involved.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.ticker import MaxNLocator

# Distinct styles: per-modality rows solid, fusions dashed, the baseline black.
_STYLE: dict[str, dict[str, Any]] = {
    "gdm": dict(color="tab:blue", linestyle="-"),
    "ddt": dict(color="tab:orange", linestyle="-"),
    "spectrum": dict(color="tab:green", linestyle="-"),
    "gdm+ddt sum": dict(color="tab:red", linestyle="--"),
    "gdm+ddt product": dict(color="tab:purple", linestyle="--"),
    "gdm+ddt+spectrum sum": dict(color="tab:brown", linestyle=":"),
    "gdm+ddt+spectrum product": dict(color="tab:pink", linestyle=":"),
    "shapedna": dict(color="black", linestyle="-."),
}


def _save(fig: Figure, path: Path) -> None:
    FigureCanvasAgg(fig)
    fig.savefig(path, dpi=120, bbox_inches="tight")


def plot_cmc(rows: Mapping[str, Mapping[str, Any]], path: str | Path, title: str = "") -> None:
    """Recognition rate against rank, one curve per report row (Fig. 5a).

    Parameters
    ----------
    rows : row key -> row of report.json (uses ``title`` and ``cmc``).
    path : PNG file to write.
    """
    fig = Figure(figsize=(6.4, 4.8))
    ax = fig.add_subplot()
    for key, row in rows.items():
        cmc = 100.0 * np.asarray(row["cmc"])
        ranks = np.arange(1, cmc.size + 1)
        ax.plot(ranks, cmc, marker="o", markersize=3, label=row["title"], **_STYLE.get(key, {}))
    ax.set_xlabel("rank")
    ax.set_ylabel("recognition rate (%)")
    ax.set_title(title or "CMC")
    ax.set_xlim(left=1)
    ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=7, loc="lower right")
    _save(fig, Path(path))


def plot_roc(rows: Mapping[str, Mapping[str, Any]], path: str | Path, title: str = "") -> None:
    """FRR against FAR on a log FAR axis, one curve per report row (Fig. 5b).

    The dotted diagonal FRR = FAR crosses each curve at its EER.

    Parameters
    ----------
    rows : row key -> row of report.json (uses ``title``, ``roc`` and ``eer``).
    path : PNG file to write.
    """
    fig = Figure(figsize=(6.4, 4.8))
    ax = fig.add_subplot()
    smallest = 1.0
    for key, row in rows.items():
        far = np.asarray(row["roc"]["far"])
        frr = np.asarray(row["roc"]["frr"])
        shown = far > 0  # log axis
        if shown.any():
            smallest = min(smallest, far[shown].min())
        label = f"{row['title']} (EER {100 * row['eer']:.1f}%)"
        ax.step(far[shown], frr[shown], where="post", label=label, **_STYLE.get(key, {}))
    grid = np.geomspace(smallest, 1.0, 50)
    ax.plot(grid, grid, color="grey", linestyle=":", linewidth=0.8)
    ax.set_xscale("log")
    ax.set_xlim(smallest, 1.0)
    ax.set_ylim(-0.01, 1.0)  # keep curves lying on FRR = 0 visible
    ax.set_xlabel("false acceptance rate (FAR)")
    ax.set_ylabel("false rejection rate (FRR)")
    ax.set_title(title or "ROC")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7, loc="upper right")
    _save(fig, Path(path))


def plot_report(report: Mapping[str, Any], out_dir: str | Path) -> None:
    """Write ``cmc.png`` and ``roc.png`` of a report into ``out_dir``."""
    out = Path(out_dir)
    name = f"{report['preset']['name']} v{report['preset']['version']}"
    plot_cmc(report["rows"], out / "cmc.png", title=f"CMC, {name}")
    plot_roc(report["rows"], out / "roc.png", title=f"ROC, {name}")
