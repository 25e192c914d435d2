"""Summaries and tables of the merge benchmark's per-pair rows."""

from __future__ import annotations

import csv
import io
import json
import math
import statistics
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from mrslam_env.atomic import write_text_atomic

FloatArray = NDArray[np.float64]


def _rate(numerator: int, denominator: int) -> float:
    return numerator / denominator if denominator else math.nan


def _median(values: list[float]) -> float:
    return statistics.median(values) if values else math.nan


def _percentile(values: list[float], q: float) -> float:
    return float(np.percentile(values, q)) if values else math.nan


def summarize(
    rows: Sequence[dict[str, Any]],
    methods: Sequence[str],
    *,
    high_overlap: float = 0.3,
    small_side: int = 400,
) -> dict[str, dict[str, Any]]:
    """Per method: the benchmark's figures.

    Keys: ``pairs``; ``success_rate_high`` (successes over pairs with overlap >=
    ``high_overlap``) with ``pairs_high``; ``success_rate_overlapping`` over all
    overlapping pairs with ``pairs_overlapping``; ``wrong`` (count) and ``wrong_rate`` (over
    all pairs); ``correct_refusals`` and ``refusal_rate`` over the ``pairs_no_overlap``;
    ``median_/p90_translation_error`` (m) and ``median_/p90_rotation_error_deg`` over the
    transforms returned on overlapping pairs; ``proposal_recall_overlapping`` over the
    ``pairs_recall`` overlapping pairs whose rows carry ``proposal_hit`` (NaN for a method
    without candidates); ``median_seconds`` per pair (wall time), ``median_cpu_seconds``
    (CPU time; NaN for rows without it), and
    ``median_seconds_small`` over the ``pairs_small`` whose grids are at most
    ``small_side`` cells on a side; ``wrong_as_good_as_truth``: wrong answers on
    overlapping pairs whose :func:`cell_agreement` is at least the truth's (the maps alone
    cannot tell them apart). When the rows carry an ``aliasing`` label
    (:mod:`scenarios.bench.merge.aliasing`; the CLI adds it), also ``pairs_high_clear`` and
    ``success_rate_high_clear``: the pairs with overlap >= ``high_overlap`` whose maps single
    out the truth (label ``clear``), and the successes among them. When the rows carry
    ``undecidable`` (:mod:`scenarios.bench.merge.twins`; the CLI adds it):
    ``pairs_high_undecidable`` and ``pairs_high_decidable`` (overlap >= ``high_overlap``), the
    ``success_rate_high_decidable``, and ``wrong_undecidable`` (wrong answers on undecidable
    pairs, any overlap).
    """
    summary: dict[str, dict[str, Any]] = {}
    for name in methods:
        mine = [row for row in rows if row["method"] == name]
        overlapping = [row for row in mine if row["overlapping"]]
        high = [row for row in overlapping if row["overlap"] >= high_overlap]
        clear = [row for row in high if row.get("aliasing") == "clear"]
        decidable = [row for row in high if row.get("undecidable") is False]
        none = [row for row in mine if not row["overlapping"]]
        returned = [row for row in overlapping if row["returned"]]
        translation = [row["translation_error"] for row in returned]
        rotation = [row["rotation_error_deg"] for row in returned]
        small = [row for row in mine if row.get("largest_side_cells", 0) <= small_side]
        recall = [bool(r["proposal_hit"]) for r in overlapping if r.get("proposal_hit") is not None]
        wrong = sum(row["outcome"] == "wrong" for row in mine)
        refusals = sum(row["outcome"] == "correct_refusal" for row in none)
        summary[name] = {
            "pairs": len(mine),
            "pairs_high": len(high),
            "success_rate_high": _rate(sum(r["outcome"] == "success" for r in high), len(high)),
            "aliasing_labelled": any(row.get("aliasing") for row in mine),
            "pairs_high_clear": len(clear),
            "success_rate_high_clear": _rate(
                sum(r["outcome"] == "success" for r in clear), len(clear)
            ),
            "twins_labelled": any(row.get("undecidable") is not None for row in mine),
            "pairs_high_undecidable": sum(bool(row.get("undecidable")) for row in high),
            "pairs_high_decidable": len(decidable),
            "success_rate_high_decidable": _rate(
                sum(r["outcome"] == "success" for r in decidable), len(decidable)
            ),
            "wrong_undecidable": sum(
                r["outcome"] == "wrong" and bool(r.get("undecidable")) for r in mine
            ),
            "pairs_overlapping": len(overlapping),
            "success_rate_overlapping": _rate(
                sum(r["outcome"] == "success" for r in overlapping), len(overlapping)
            ),
            "wrong": wrong,
            "wrong_rate": _rate(wrong, len(mine)),
            "pairs_no_overlap": len(none),
            "correct_refusals": refusals,
            "refusal_rate": _rate(refusals, len(none)),
            "median_translation_error": _percentile(translation, 50),
            "p90_translation_error": _percentile(translation, 90),
            "median_rotation_error_deg": _percentile(rotation, 50),
            "p90_rotation_error_deg": _percentile(rotation, 90),
            "median_seconds": _median([r["seconds"] for r in mine]),
            "median_cpu_seconds": _median(
                [r["cpu_seconds"] for r in mine if r.get("cpu_seconds") is not None]
            ),
            "pairs_small": len(small),
            "median_seconds_small": _median([r["seconds"] for r in small]),
            "wrong_as_good_as_truth": sum(
                r["outcome"] == "wrong"
                and r["overlapping"]
                and r["agreement_estimate"] is not None
                and r["agreement_estimate"] >= r["agreement_truth"]
                for r in mine
            ),
            "pairs_recall": len(recall),
            "proposal_recall_overlapping": _rate(sum(recall), len(recall)),
        }
    return summary


def _percent(value: float) -> str:
    return "-" if math.isnan(value) else f"{100 * value:.0f}%"


def _number(value: float, digits: int) -> str:
    return "-" if math.isnan(value) else f"{value:.{digits}f}"


def format_merge_table(
    summary: Mapping[str, Mapping[str, Any]],
    skipped: Mapping[str, str] | None = None,
    *,
    high_overlap: float = 0.3,
) -> str:
    """A markdown table, methods side by side, one figure per row (skipped methods listed
    below it)."""
    names = list(summary)
    if not names:
        lines = ["(no method ran)"]
    else:
        first = summary[names[0]]
        rows: list[tuple[str, Callable[[Mapping[str, Any]], str]]] = [
            (
                f"success, overlap ≥ {100 * high_overlap:.0f}% (n={first['pairs_high']})",
                lambda s: _percent(s["success_rate_high"]),
            ),
            *(
                [
                    (
                        f"success, overlap ≥ {100 * high_overlap:.0f}%, maps single out the "
                        f"truth (n={first['pairs_high_clear']})",
                        lambda s: _percent(s["success_rate_high_clear"]),
                    )
                ]
                if first.get("aliasing_labelled")
                else []
            ),
            *(
                [
                    (
                        f"success, overlap ≥ {100 * high_overlap:.0f}%, decidable pairs "
                        f"(n={first['pairs_high_decidable']})",
                        lambda s: _percent(s["success_rate_high_decidable"]),
                    )
                ]
                if first.get("twins_labelled")
                else []
            ),
            (
                f"success, all overlapping (n={first['pairs_overlapping']})",
                lambda s: _percent(s["success_rate_overlapping"]),
            ),
            (
                f"wrong answers, all pairs (n={first['pairs']})",
                lambda s: f"{s['wrong']} ({_percent(s['wrong_rate'])})",
            ),
            (
                f"correct refusals, no overlap (n={first['pairs_no_overlap']})",
                lambda s: f"{s['correct_refusals']} ({_percent(s['refusal_rate'])})",
            ),
            (
                "translation error median / p90 (m)",
                lambda s: (
                    f"{_number(s['median_translation_error'], 3)} / "
                    f"{_number(s['p90_translation_error'], 3)}"
                ),
            ),
            (
                "rotation error median / p90 (°)",
                lambda s: (
                    f"{_number(s['median_rotation_error_deg'], 2)} / "
                    f"{_number(s['p90_rotation_error_deg'], 2)}"
                ),
            ),
            ("median time per pair (s)", lambda s: _number(s["median_seconds"], 2)),
            ("median CPU time per pair (s)", lambda s: _number(s["median_cpu_seconds"], 2)),
            (
                f"median time, grids ≤ 400×400 (n={first['pairs_small']}) (s)",
                lambda s: _number(s["median_seconds_small"], 2),
            ),
            (
                "wrong answers agreeing as well as the truth",
                lambda s: str(s["wrong_as_good_as_truth"]),
            ),
            *(
                [
                    (
                        "proposal recall, overlapping pairs (truth within 0.5 m / 3° among "
                        "the candidates)",
                        lambda s: _percent(s.get("proposal_recall_overlapping", math.nan)),
                    )
                ]
                if any(summary[n].get("pairs_recall") for n in names)
                else []
            ),
        ]
        header = "| | " + " | ".join(names) + " |"
        lines = [header, "|---|" + "---:|" * len(names)]
        for label, cell in rows:
            lines.append(f"| {label} | " + " | ".join(cell(summary[n]) for n in names) + " |")
    for name, reason in (skipped or {}).items():
        lines.append(f"\nskipped {name}: {reason}")
    return "\n".join(lines)


def format_family_breakdown(
    rows: Sequence[dict[str, Any]], methods: Sequence[str], *, high_overlap: float = 0.3
) -> str:
    """Each method per world family (``built-in`` / ``real``, the rows' ``family``), as a
    markdown table: success at overlap >= ``high_overlap`` and on all overlapping pairs,
    wrong answers, correct refusals, proposal recall and the median time."""
    families = sorted({row.get("family", "built-in") for row in rows})
    lines = [
        f"| method | worlds | pairs | success, overlap ≥ {100 * high_overlap:.0f}% | "
        "success, overlapping | wrong | correct refusals | proposal recall | median s |",
        "| --- | --- |" + " ---: |" * 7,
    ]
    for name in methods:
        for family in families:
            mine = [r for r in rows if r.get("family", "built-in") == family]
            figures = summarize(mine, [name], high_overlap=high_overlap)[name]
            if not figures["pairs"]:
                continue
            lines.append(
                f"| {name} | {family} | {figures['pairs']} | "
                f"{_percent(figures['success_rate_high'])} (n={figures['pairs_high']}) | "
                f"{_percent(figures['success_rate_overlapping'])} "
                f"(n={figures['pairs_overlapping']}) | {figures['wrong']} | "
                f"{figures['correct_refusals']}/{figures['pairs_no_overlap']} | "
                f"{_percent(figures['proposal_recall_overlapping'])} | "
                f"{_number(figures['median_seconds'], 2)} |"
            )
    return "\n".join(lines)


def format_scenario_breakdown(rows: Sequence[dict[str, Any]], method: str = "ours") -> str:
    """Outcomes of one method per world (procedural layouts together), as a markdown
    table: where it succeeds, and where it refuses because the maps are ambiguous."""
    counts: dict[str, dict[str, int]] = {}
    for row in rows:
        if row["method"] != method:
            continue
        world = "procedural" if row["scenario"].startswith("procedural") else row["scenario"]
        tally = counts.setdefault(world, {})
        tally[row["outcome"]] = tally.get(row["outcome"], 0) + 1
    outcomes = ("success", "refused", "wrong", "correct_refusal")
    lines = [
        f"| {method}: world | " + " | ".join(o.replace("_", " ") for o in outcomes) + " |",
        "| --- |" + " ---: |" * len(outcomes),
    ]
    for world in sorted(counts):
        lines.append(
            f"| {world} | " + " | ".join(str(counts[world].get(o, 0)) for o in outcomes) + " |"
        )
    return "\n".join(lines)


def format_aliasing_breakdown(
    rows: Sequence[dict[str, Any]], method: str = "ours", *, high_overlap: float = 0.3
) -> str:
    """Outcomes of one method on the pairs with overlap >= ``high_overlap`` by their
    ``aliasing`` label (:mod:`scenarios.bench.merge.aliasing`), as a markdown table; empty when the
    rows carry no labels."""
    mine = [
        r
        for r in rows
        if r["method"] == method and r["overlapping"] and r["overlap"] >= high_overlap
    ]
    if not any(r.get("aliasing") for r in mine):
        return ""
    outcomes = ("success", "refused", "wrong")
    lines = [
        f"| {method}: the maps, overlap ≥ {100 * high_overlap:.0f}% | pairs | "
        + " | ".join(outcomes)
        + " |",
        "| --- | ---: |" + " ---: |" * len(outcomes),
    ]
    for label, meaning in (
        ("clear", "single out the truth"),
        ("close", "fit a wrong placement nearly as well"),
        ("misleading", "fit a wrong placement as well or better"),
    ):
        group = [r for r in mine if r.get("aliasing") == label]
        counts = " | ".join(str(sum(r["outcome"] == o for r in group)) for o in outcomes)
        lines.append(f"| {label}: {meaning} | {len(group)} | {counts} |")
    dominated = [r for r in mine if r.get("aliasing_dominated")]
    if dominated:
        counts = " | ".join(str(sum(r["outcome"] == o for r in dominated)) for o in outcomes)
        lines.append(
            f"| of all these, a wrong placement overlaps as much or more, no more conflicts "
            f"| {len(dominated)} | {counts} |"
        )
    return "\n".join(lines)


def format_twin_breakdown(
    rows: Sequence[dict[str, Any]], method: str = "ours", *, high_overlap: float = 0.3
) -> str:
    """Outcomes of one method on the pairs whose maps arise from a second start too
    (``undecidable``, :mod:`scenarios.bench.merge.twins`) and on the rest, as a markdown
    table with the success ceiling they set; empty when the rows carry no such label."""
    mine = [r for r in rows if r["method"] == method and r.get("undecidable") is not None]
    if not mine:
        return ""
    outcomes = ("success", "refused", "wrong", "correct_refusal")
    lines = [
        f"| {method}: can the maps decide? | pairs | "
        + " | ".join(o.replace("_", " ") for o in outcomes)
        + " |",
        "| --- | ---: |" + " ---: |" * len(outcomes),
    ]
    high = [r for r in mine if r["overlapping"] and r["overlap"] >= high_overlap]
    groups = (
        (f"overlap ≥ {100 * high_overlap:.0f}%, decidable", high, False),
        (f"overlap ≥ {100 * high_overlap:.0f}%, undecidable", high, True),
        (
            f"overlap < {100 * high_overlap:.0f}%, undecidable",
            [r for r in mine if r["overlapping"] and r["overlap"] < high_overlap],
            True,
        ),
        ("no overlap, undecidable", [r for r in mine if not r["overlapping"]], True),
    )
    for label, group, undecidable in groups:
        members = [r for r in group if bool(r["undecidable"]) == undecidable]
        counts = " | ".join(str(sum(r["outcome"] == o for r in members)) for o in outcomes)
        lines.append(f"| {label} | {len(members)} | {counts} |")
    if high:
        share = sum(not r["undecidable"] for r in high) / len(high)
        lines.append(
            f"\nUndecidable: the same two maps arise from a second pair of starts with another "
            f"ground truth. Refusing those, no method passes {_percent(share)} at overlap "
            f"≥ {100 * high_overlap:.0f}%; merging one is a wrong answer on its twin."
        )
    return "\n".join(lines)


def write_rows(path: Path, rows: Sequence[dict[str, Any]], extra: dict[str, Any]) -> Path:
    """Per-pair rows to ``path``: CSV when it ends in ``.csv``, else JSON (with ``extra``,
    e.g. the summary and the manifest's generation figures)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    if path.suffix.lower() == ".csv":  # built in memory, then written atomically
        text = io.StringIO(newline="")
        fields = list(dict.fromkeys(key for row in rows for key in row)) or ["pair_id"]
        writer = csv.DictWriter(text, fieldnames=fields, restval="")
        writer.writeheader()
        writer.writerows(rows)
        write_text_atomic(path, text.getvalue())
    else:
        write_text_atomic(path, json.dumps({**extra, "rows": list(rows)}, indent=2, default=float))
    return path
