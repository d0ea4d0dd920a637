"""report.json and report.md: the protocol in words, the rows' numbers, the errors, timings."""

from __future__ import annotations

import platform
import time
from collections import Counter
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from worker.engine.presets import MODALITIES, PARTS, SIZE, Preset
from worker.recognition import metrics

from .cache import engine_fingerprint
from .compute import ComputedSet, descriptor_vectors
from .partial import ORBITING, RANGE_ELEVATION
from .partiality import collection_matrices
from .robustness import PRESET_ROW
from .scoring import COLUMNS, dissimilarity_matrices, report_rows, score_dissimilarity
from .shapedna import BASELINE, SHAPEDNA_K


def protocol_text(
    preset: Preset, n_objects: int, n_classes: int, gallery: Sequence[str]
) -> dict[str, Any]:
    """The protocol in words, for report.json and report.md."""
    sigma = (
        "D2 (eq. 9), sigma_i = standard deviation of descriptor element i over all "
        f"{n_objects} evaluated objects (all-to-all protocol: the whole set is the gallery)"
        if preset.dissimilarity == "D2"
        else "D1 (eq. 8), mean normalized Manhattan distance"
    )
    weighed = (*MODALITIES, SIZE) if preset.units == "metric" else MODALITIES
    weights = ", ".join(f"{m}={preset.weight(m):g}" for m in weighed)
    units = {}
    if preset.units == "metric":
        units["units"] = (
            "metric: the size sqrt(A) of each file's described surface (A its area in the "
            f"file's units) compared by eq. (8), D1, at least {preset.size_tolerance:g}, "
            "fused with the shape's modalities"
        )
    return {
        "objects": n_objects,
        "classes": n_classes,
        "dissimilarity": sigma,
        "fusion": (
            "sum = sum_m w_m D_m, product = prod_m D_m ** w_m over the raw per-modality "
            f"matrices, preset weights ({weights})"
        ),
        "preset_score": "+".join(preset.scored_modalities) + f" {preset.fusion}",
        **units,
        "verification": (
            f"all {n_objects * (n_objects - 1) // 2} unordered pairs; genuine = same class; "
            "ROC = FRR against FAR over the threshold; EER where FRR = FAR"
        ),
        "identification": (
            f"gallery = first instance of each class in natural file-name order "
            f"({n_classes} objects: {', '.join(gallery)}); probes = the other "
            f"{n_objects - n_classes}; CMC with pessimistic ties; R1RR = CMC at rank 1"
        ),
        "retrieval": (
            "leave-one-out, each object queries the other n-1; NN, first tier, second "
            "tier, E-measure (top 32), normalized DCG, mean average precision; ties "
            "broken by file order"
        ),
        "baseline": (
            f"ShapeDNA via lapy on the same resampled mesh ({preset.n_vertices} vertices): "
            f"compute_shapedna(k={SHAPEDNA_K}), normalize_ev(method='geometry') "
            "(times surface area), reweight_ev (lambda_i / i), compute_distance(dist='euc')"
        ),
    }


def _mean_timings(timings: Sequence[Mapping[str, float]]) -> dict[str, float]:
    keys = sorted({k for t in timings for k in t})
    return {k: float(np.mean([t[k] for t in timings if k in t])) for k in keys}


def build_report(
    computed: ComputedSet,
    preset: Preset,
    *,
    command: str = "",
    environment: Mapping[str, str] | None = None,
    dataset: str = "",
    jobs: int = 1,
) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    """Dissimilarities and metrics of every row, as one JSON-ready dict.

    Parameters
    ----------
    computed : the described set (:func:`compute_descriptors`).
    preset : the preset the descriptors were made with.
    command, environment, dataset : recorded as given.
    jobs : processes comparing the parts modality.

    Returns
    -------
    report : dict, see report.json.
    matrices : row key -> (n, n) dissimilarity matrix.
    """
    start = time.perf_counter()
    names = [m.name for m in computed.meshes]
    labels = [m.label for m in computed.meshes]
    vectors = descriptor_vectors(computed, size=preset.units == "metric")
    matrices, info = dissimilarity_matrices(vectors, preset, vectors[BASELINE])
    rows_of = report_rows(preset)
    titles = {key: rows_of[key] for key in matrices}
    if preset.has_parts:
        baseline = matrices.pop(BASELINE)  # stays the last row
        matrices.update(collection_matrices(computed.descriptors, matrices, preset, jobs))
        matrices[BASELINE] = baseline
        titles[PARTS] = ("Parts", (PARTS,), None)
        titles[PRESET_ROW] = (
            "The preset's score (parts by partiality)",
            (*preset.scored_modalities, PARTS),
            "product",
        )
    gallery_idx, probe_idx = metrics.first_instance_split(names, labels)
    rows = {}
    for key, matrix in matrices.items():
        title, members, rule = titles[key]
        rows[key] = {
            "title": title,
            "members": list(members),
            "rule": rule,
            **{k: v for k, v in info.get(key, {}).items() if k != "sigma"},
            **score_dissimilarity(matrix, labels, names, gallery_idx, probe_idx),
        }
    metrics_seconds = time.perf_counter() - start
    classes = Counter(labels)
    gallery = [names[i] for i in gallery_idx]
    d2_sigma = {m: info[m]["sigma"].tolist() for m in MODALITIES if "sigma" in info[m]}
    report = {
        "dataset": dataset,
        "command": command,
        "preset": preset.to_dict(),
        "protocol": protocol_text(preset, len(names), len(classes), gallery),
        "objects": [
            {"file": n, "class": c, "gallery": n in gallery}
            for n, c in zip(names, labels, strict=True)
        ],
        "class_sizes": dict(sorted(classes.items())),
        "failures": computed.failures,
        "rows": rows,
        "d2_sigma": d2_sigma,
        "timings": {
            **computed.stats,
            "metrics_seconds": metrics_seconds,
            "descriptor_stage_seconds_mean": _mean_timings(
                [d.timings for d in computed.descriptors]
            ),
            "shapedna_seconds_mean": float(np.mean([b.seconds for b in computed.baselines])),
            "note": (
                "per-mesh stage times are those recorded when each descriptor was "
                "computed (possibly in an earlier run, under other load)"
            ),
        },
        "environment": dict(environment or {}),
    }
    return report, matrices


def _pct(value: float, digits: int) -> str:
    return f"{100.0 * value:.{digits}f}"


def _confusion_summary(errors: Sequence[Mapping[str, str]], true_key: str, got_key: str) -> str:
    pairs = Counter((e[true_key], e[got_key]) for e in errors)
    return ", ".join(f"{a}->{b} x{c}" for (a, b), c in sorted(pairs.items(), key=lambda x: -x[1]))


def render_markdown(report: Mapping[str, Any]) -> str:
    """report.md: the protocol, the table (percent) and which classes were confused."""
    protocol = report["protocol"]
    preset = report["preset"]
    lines = [
        f"# Evaluation: preset `{preset['name']}` v{preset['version']}",
        "",
        f"Dataset: `{report['dataset']}`, {protocol['objects']} objects, "
        f"{protocol['classes']} classes "
        f"({', '.join(f'{k} {v}' for k, v in report['class_sizes'].items())}).",
        "",
        f"Command: `{report['command'] or '(not recorded)'}`",
        "",
        "All numbers in percent. NN, FT, ST, E, DCG, mAP: leave-one-out retrieval; "
        "R1RR: identification; EER: verification (lower is better). "
        f"The preset's own score is **{protocol['preset_score']}**.",
        "",
        "| | " + " | ".join(COLUMNS.values()) + " |",
        "|---|" + "---:|" * len(COLUMNS),
    ]
    for row in report["rows"].values():
        cells = [_pct(row[k], 2 if k == "eer" else 1) for k in COLUMNS]
        lines.append(f"| {row['title']} | " + " | ".join(cells) + " |")
    lines += ["", "## Protocol", ""]
    lines += [f"- **{key}**: {text}" for key, text in protocol.items()]
    if "resampling" in report:
        lines += _resampling_markdown(report["resampling"])
    lines += ["", "## Errors", "", "| | NN errors (class->nearest) | R1 errors (class->match) |"]
    lines.append("|---|---|---|")
    for row in report["rows"].values():
        nn = _confusion_summary(row["nn_errors"], "class", "nearest_class") or "none"
        r1 = _confusion_summary(row["rank1_errors"], "class", "matched_class") or "none"
        lines.append(f"| {row['title']} | {nn} | {r1} |")
    if "learned_fusion" in report:
        lines += _learned_markdown(report["learned_fusion"])
    if report["failures"]:
        lines += ["", "## Meshes left out", ""]
        lines += [f"- `{name}`: {why}" for name, why in report["failures"].items()]
    timings = report["timings"]
    lines += [
        "",
        "## Timings",
        "",
        f"{timings['meshes']} meshes: {timings['from_cache']} from cache, "
        f"{timings['computed']} computed in {timings['compute_seconds']:.1f} s "
        f"with {timings['jobs']} worker process(es); metrics {timings['metrics_seconds']:.1f} s. "
        "Mean seconds per mesh when computed: "
        + ", ".join(f"{k} {v:.2f}" for k, v in timings["descriptor_stage_seconds_mean"].items())
        + f"; ShapeDNA {timings['shapedna_seconds_mean']:.2f}.",
        "",
        "![CMC](cmc.png) ![ROC](roc.png)",
        "",
    ]
    return "\n".join(lines)


def _resampling_markdown(resampling: Mapping[str, Any]) -> list[str]:
    """How the meshes were resampled when once per figure (``--resampling figure``)."""
    lines = [
        "",
        "## Resampling: one per figure",
        "",
        "Each class's first file was resampled and its resampling carried to the class's "
        "files of as many vertices through their shared vertex ids.",
        "",
        "| class | made on | vertices | files that took it |",
        "|---|---|---:|---:|",
    ]
    for label, figure in resampling["figures"].items():
        lines.append(
            f"| {label} | `{figure['made_on']}` | {figure['vertices']} | {figure['poses']} |"
        )
    own = resampling["resampled_on_their_own"]
    shown = ", ".join(f"`{name}`" for name in own) if own else "none"
    lines += [
        "",
        f"Resampled on their own (another vertex count than their class's first): {shown}.",
    ]
    return lines


def _learned_markdown(learned: Mapping[str, Any]) -> list[str]:
    """Each fold's choice and its held-out figures beside the preset's weights'."""

    def choice(weights: Mapping[str, float], comparisons: Mapping[str, str]) -> str:
        return ", ".join(f"{m} {w:g} ({comparisons[m]})" for m, w in weights.items())

    lines = [
        "",
        "## Learned fusion",
        "",
        "Each fold's choice on the other folds' meshes, and its figures on the fold's own "
        "(EER over the pairs involving them; mAP with them as queries), beside the preset's "
        "weights on the same meshes.",
        "",
        "| fold | meshes | weights (comparison) | EER | mAP | preset's EER | preset's mAP |",
        "|---|---:|---|---:|---:|---:|---:|",
    ]
    for i, fold in enumerate(learned["folds"]):
        own, base = fold["held_out"]["learned"], fold["held_out"]["preset"]
        lines.append(
            f"| {i} | {fold['held_out_objects']} | "
            f"{choice(fold['weights'], fold['comparisons'])} | {_pct(own['eer'], 2)} | "
            f"{_pct(own['map'], 1)} | {_pct(base['eer'], 2)} | {_pct(base['map'], 1)} |"
        )
    own, base = learned["held_out"]["learned"], learned["held_out"]["preset"]
    chosen, test = learned["chosen_on_all"], learned["adoption"]
    lines += [
        f"| mean | | | {_pct(own['eer'], 2)} | {_pct(own['map'], 1)} | "
        f"{_pct(base['eer'], 2)} | {_pct(base['map'], 1)} |",
        "",
        f"Chosen on every mesh: {choice(chosen['weights'], chosen['comparisons'])}. "
        f"A gallery decides on {test['rounds']} rounds of the folds: their gain over the "
        f"preset's weights, {100 * test['gain']:.2f} points of the mean of EER and 1 - mAP, "
        f"has a corrected resampled t of {test['statistic']:.2f} against "
        f"{test['critical']:.2f} ({100 * test['confidence']:g}%, one-sided), so it "
        + ("would adopt the learned fusion." if test["adopted"] else "would keep the preset's."),
    ]
    return lines


def environment_info() -> dict[str, str]:
    """Versions that can change the numbers."""
    import lapy
    import scipy

    return {
        "python": platform.python_version(),
        "numpy": np.__version__,
        "scipy": scipy.__version__,
        "lapy": lapy.__version__,
        "engine_fingerprint": engine_fingerprint()[:16],
    }


def render_robustness_markdown(report: Mapping[str, Any]) -> str:
    """robustness.md: per row, class and self retrieval of the variants and the gap."""
    preset = report["preset"]
    titles = report["rows"]
    scores = report["tessellation"]
    variants = report["variants"]
    lines = [
        f"# Tessellation robustness: preset `{preset['name']}` v{preset['version']}",
        "",
        f"Dataset: `{report['dataset']}`. Command: `{report['command'] or '(not recorded)'}`",
        "",
        "Every mesh is described as given and as each of its variants (same surface, other "
        "triangles: " + ", ".join(f"`{v}`" for v in variants) + "). **class**: the variant's "
        "nearest original, its own source left out, is of its class. **self**: with its source "
        "in the gallery, the nearest original is its source (no bar). **gap**: median distance "
        "mesh-variant over the median distance from a mesh to the nearest mesh of another "
        f"class (bar: below {report['gap_bar']}).",
        "",
        "| | class | self | gap | meets the bar |",
        "|---|---:|---:|---:|---|",
    ]
    for key, title in titles.items():
        if key not in scores:
            continue
        row = scores[key]
        lines.append(
            f"| {title} | {_pct(row['class_retrieval'], 1)} | {_pct(row['self_retrieval'], 1)} "
            f"| {row['gap']:.3f} | {'yes' if row['passes'] else 'no'} |"
        )
    lines += ["", "Per variant (class % / self % / gap):", ""]
    lines.append("| | " + " | ".join(variants) + " |")
    lines.append("|---|" + "---:|" * len(variants))
    for key, title in titles.items():
        if key not in scores:
            continue
        cells = [
            f"{_pct(v['class_retrieval'], 0)} / {_pct(v['self_retrieval'], 0)} / {v['gap']:.2f}"
            for v in (scores[key]["variants"][name] for name in variants)
        ]
        lines.append(f"| {title} | " + " | ".join(cells) + " |")
    if "input_vertices" in report:
        totals = report["input_vertices"]
        lines += [
            "",
            f"Input vertices, summed over the meshes (originals: {totals['original']:,}); "
            "two reports compare only if these agree, i.e. they described the same variant "
            "meshes:",
            "",
            "| " + " | ".join(variants) + " |",
            "|" + "---:|" * len(variants),
            "| " + " | ".join(f"{totals[name]:,}" for name in variants) + " |",
        ]
    if "poses" in report:
        poses = report["poses"]["scores"]
        count = next(iter(poses.values()))["poses"]
        lines += [
            "",
            f"## Pose invariance: `{report['poses']['dataset']}` ({count} poses of one object)",
            "",
            "In one gallery with the collection. **ratio**: median distance between two poses "
            "over the median distance between two objects of different classes of the "
            "collection. **foreign**: poses whose nearest neighbour is not another pose.",
            "",
            "| | ratio | foreign |",
            "|---|---:|---:|",
        ]
        for key, title in titles.items():
            if key in poses:
                lines.append(
                    f"| {title} | {poses[key]['ratio']:.3f} | {poses[key]['foreign_nearest']} |"
                )
        strays = [
            f"- {titles[key]}: " + ", ".join(f"`{pose}` (nearest `{near}`)" for pose, near in found)
            for key in titles
            if key in poses and (found := poses[key].get("foreign"))
        ]
        if strays:
            lines += ["", "Poses nearest a mesh of the collection:", "", *strays]
        if "cross_resolution" in report["poses"]:
            across = report["poses"]["cross_resolution"]
            first, second = report["poses"]["resolutions"]
            count = next(iter(across.values()))["poses"]
            lines += [
                "",
                f"Cross-resolution pose retrieval ({count} poses as `{first}` and as "
                f"`{second}`): every pose at one resolution queries the poses at the other. "
                "**rank 1**: its own pose is the nearest. **ratio**: median distance to its "
                "own pose at the other resolution over the distance to the nearest other "
                "pose at its own (below 1: the resolution moves a pose less than the next "
                "pose is away).",
                "",
                "| | rank 1 | ratio |",
                "|---|---:|---:|",
            ]
            for key, title in titles.items():
                if key in across:
                    row = across[key]
                    lines.append(f"| {title} | {_pct(row['rank1'], 1)} | {row['ratio']:.3f} |")
    if report["failures"]:
        lines += ["", "## Meshes that could not be described", ""]
        for name, why in report["failures"].items():
            lines += [f"- `{name}` ({variant}): {text}" for variant, text in why.items()]
    lines.append("")
    return "\n".join(lines)


def _variant_table(
    rows: Mapping[str, str],
    scores: Mapping[str, Mapping[str, Mapping[str, float]]],
    variants: list[str],
    keys: tuple[str, ...],
) -> list[str]:
    """A markdown table: a line per row key of ``scores`` (titled by ``rows``), a column
    per variant, each cell the ``keys``' scores in % joined by " / "."""
    lines = ["| | " + " | ".join(variants) + " |", "|---|" + "---:|" * len(variants)]
    for key, title in rows.items():
        if key in scores:
            cells = [" / ".join(_pct(scores[key][v][k], 1) for k in keys) for v in variants]
            lines.append(f"| {title} | " + " | ".join(cells) + " |")
    return lines


#: Class pairs partiality.md lists of each variant's all-to-all misses.
MISSES_SHOWN = 8


def _misses(misses: Mapping[str, Mapping[str, int]]) -> str:
    """ "a -> b 9, c -> b 7, ..." of :func:`~worker.recognition.metrics.nearest_neighbor_misses`'
    counts, the largest first (ties by name), at most :data:`MISSES_SHOWN`; "none"."""
    pairs = sorted(
        (
            (-count, asked, answered)
            for asked, to in misses.items()
            for answered, count in to.items()
        )
    )
    shown = ", ".join(f"{a} -> {b} {-c}" for c, a, b in pairs[:MISSES_SHOWN])
    rest = sum(-c for c, _, _ in pairs[MISSES_SHOWN:])
    return (shown or "none") + (f"; {rest} more" if rest else "")


def render_partiality_markdown(report: Mapping[str, Any]) -> str:
    """partiality.md: per row and partial variant, own class, own source and mAP."""
    preset = report["preset"]
    about = report["variants"]
    variants = list(about)
    poses = f" and the poses of `{report['poses']}` (one more class)" if report["poses"] else ""
    copies = report.get("copies", 1)
    drawn = f", each drawn {copies} times with seeds of its own" if copies > 1 else ""
    up = report.get("up")
    if up and any(v in ORBITING for v in variants):
        theirs = (
            f", the poses' {up['poses']}" if up["poses"] and up["poses"] != up["dataset"] else ""
        )
        drawn += (
            f"; the range camera orbits the axis the files stand on ({up['dataset']}{theirs}) "
            f"within {RANGE_ELEVATION:g} degrees of the horizon"
        )
    lines = [
        f"# Partial queries: preset `{preset['name']}` v{preset['version']}",
        "",
        f"Gallery: the {report['wholes']} whole meshes of `{report['dataset']}`{poses}. "
        f"Command: `{report['command'] or '(not recorded)'}`",
        "",
        "Every mesh's partial copies (" + ", ".join(f"`{v}`" for v in variants) + f"{drawn}) "
        "query the whole meshes. Per cell: **own class** at rank 1 / **own source** at rank 1 / "
        "**mAP** (the query's class relevant), in %.",
        "",
        *_variant_table(
            report["rows"], report["scores"], variants, ("own_class", "own_source", "map")
        ),
    ]
    if all("class_mean" in cells[v] for cells in report["scores"].values() for v in cells):
        lines += [
            "",
            "Own class at rank 1 averaged over the queries' classes, each class's copies "
            "weighing alike, in %: always answering one class scores one over the number "
            "of classes here, and above its share of the copies (the last table's "
            "largest class).",
            "",
            *_variant_table(report["rows"], report["scores"], variants, ("class_mean",)),
        ]
    among = report.get("all_to_all") or {}
    ranked = [v for v in variants if any(v in cells for cells in among.values())]
    if ranked:
        lines += [
            "",
            "All to all among each variant's copies, as SHREC'17 ranks partial shapes: every "
            "copy queries the others of its variant. Per cell: **NN** / **1st tier** / "
            "**2nd tier** / **DCG** / **mAP**, in %.",
            "",
            *_variant_table(
                report["rows"], among, ranked, ("nn", "first_tier", "second_tier", "dcg", "map")
            ),
        ]
        missed = {
            v: among[PRESET_ROW][v]["misses"]
            for v in ranked
            if "misses" in among.get(PRESET_ROW, {}).get(v, {})
        }
        if missed:
            lines += [
                "",
                "Where the preset's NN misses go, a copy's class -> its nearest copy's, most "
                f"first (at most {MISSES_SHOWN} pairs):",
                "",
                *(f"- `{v}`: {_misses(pairs)}" for v, pairs in missed.items()),
            ]
    lines += [
        "",
        "How partial the copies look (the preset's partiality, 0 a whole, 1 wholly partial): "
        "median, and the share weighed by the parts modality at all; the share of the "
        "copies in their largest class.",
        "",
        "| | " + " | ".join(variants) + " |",
        "|---|" + "---:|" * len(variants),
        "| copies | " + " | ".join(str(about[v]["count"]) for v in variants) + " |",
        "| median partiality | "
        + " | ".join(f"{about[v]['partiality_median']:.2f}" for v in variants)
        + " |",
        "| looks partial | "
        + " | ".join(_pct(about[v]["looks_partial"], 0) for v in variants)
        + " |",
    ]
    if all("largest_class" in about[v] for v in variants):
        lines.append(
            "| largest class | "
            + " | ".join(_pct(about[v]["largest_class"], 1) for v in variants)
            + " |"
        )
    failed = report.get("failures") or {}
    if failed:
        lines += ["", "Not described (left out):", ""]
        lines += [f"- `{name}`: {why}" for name, why in failed.items()]
    return "\n".join(lines) + "\n"
