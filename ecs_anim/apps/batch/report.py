"""The batch's ``report.html``: which jobs are bad, at a glance, with their files linked.

:func:`write_report` takes the batch's job records (one dict per job, the fields of
``metrics.json``: documented in ``docs/batch.md``) and writes one self-contained HTML
file: its plots are PNGs made by matplotlib (Agg backend, no screen) embedded as base64, so the
report is a single file written atomically, that opens anywhere and can be mailed or archived
alone. Its links to a job's outputs are relative to the report's folder, which is the batch's
``DIR`` (where the records' ``outputs`` paths start).

What it shows, top to bottom:

* a summary line (jobs ok, skipped, failed; time taken);
* the failed jobs, each with its one-line error;
* foot sliding and ground penetration per body and per clip (one dot per job);
* the figures against stature (each clip's jobs joined across bodies of rising stature);
* a contact timeline per clip (when each foot is planted);
* every job, the worst first: a job's *badness* is its largest figure divided by that figure's
  tolerance (:data:`TOLERANCES`), so 1.0 is "just at the limit"; cells over their tolerance
  are marked.
"""

from __future__ import annotations

import base64
import html
import io
import math
import urllib.parse
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")  # before pyplot: a headless batch has no screen

import matplotlib.pyplot as plt
import numpy as np
from matplotlib.collections import LineCollection
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Rectangle

from ecs_anim.core.files import atomic_output
from ecs_anim.runtime.metrics import SLIDE_EVENT_MM

Job = dict[str, Any]

#: What counts as bad: a figure above its tolerance is marked in the report, and a job's badness
#: is its largest ``figure / tolerance``. Keys are job-record fields (``constraint`` stands for
#: the worst of ``constraint_errors_mm``); values are (tolerance, unit, label). The foot-skate
#: ratio is shown but not ranked: its fixed thresholds (a foot under 5 cm moving faster than
#: 2.5 cm per frame) count a child's low swing as skating, so it says as much about the clip
#: and the body's size as about the adaptation.
TOLERANCES: dict[str, tuple[float, str, str]] = {
    "slide_max_mm": (SLIDE_EVENT_MM, "mm/frame", "foot sliding in contact, max"),
    "penetration_max_mm": (1.0, "mm", "ground penetration, max"),
    "floating_max_mm": (1.0, "mm", "planted sole above the ground, max"),
    "bone_error_m": (1e-6, "m", "bone-length error"),
    "com_error_mm": (10.0, "mm", "centre-of-mass error"),
    "constraint": (10.0, "mm", "worst constraint error (fully active)"),
}

#: Clips drawn in the contact timeline (the first ones by name; the rest are counted).
MAX_TIMELINE_CLIPS = 60
#: Rows of the per-clip plot (the clips with the worst jobs; the plot says how many it left out).
MAX_CLIP_ROWS = 80
#: Resolution of the embedded plots (dots per inch).
DPI = 100

FOOT_COLOURS = {"left": "#2b6cb0", "right": "#c05621"}
#: Qualitative colours for the dots' groups (grounds, bodies), repeated beyond ten.
PALETTE = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2",
           "#7f7f7f", "#bcbd22", "#17becf")  # matplotlib's tab10


def write_report(path: Path, jobs: list[Job]) -> None:
    """Write ``path`` (the batch's ``DIR/report.html``) from the job records, atomically.

    ``jobs`` are the records of ``metrics.json`` (any order; failed and skipped ones included).
    The report is rewritten whole on every batch run: it is the batch's own summary, never a
    user's file, so it replaces an earlier one (a half-written report never appears).
    """
    page = report_html(jobs)
    with atomic_output(path, force=True) as f:
        f.write(page.encode("utf-8"))


# ---------------------------------------------------------------------------------------------
# Reading the records


def _number(job: Job, key: str) -> float | None:
    """A finite figure of a job, or None (absent, null, NaN, or the job failed)."""
    value = job.get(key)
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        return None
    return float(value)


def worst_constraint(job: Job) -> tuple[str, float] | None:
    """The constraint with the largest error of a job (name, mm), or None when it has none."""
    errors = [(name, float(mm)) for name, mm in (job.get("constraint_errors_mm") or {}).items()
              if isinstance(mm, int | float) and math.isfinite(mm)]
    return max(errors, key=lambda e: e[1]) if errors else None


def _figure(job: Job, key: str) -> float | None:
    if key == "constraint":
        worst = worst_constraint(job)
        return None if worst is None else worst[1]
    return _number(job, key)


def badness(job: Job) -> tuple[float, str]:
    """A job's largest ``figure / tolerance`` over :data:`TOLERANCES` and which figure it is
    (``(0.0, "")`` for a job with no figures)."""
    ratios = [(value / TOLERANCES[key][0], key) for key in TOLERANCES
              if (value := _figure(job, key)) is not None]
    return max(ratios) if ratios else (0.0, "")


def _measured(jobs: Sequence[Job]) -> list[Job]:
    """The jobs with figures to plot: not failed (a skipped job keeps its earlier figures)."""
    return [j for j in jobs if j.get("status") != "failed"]


def _body_order(jobs: Sequence[Job]) -> list[str]:
    """Body names by stature, then name (so the per-body plot reads from small to tall)."""
    stature: dict[str, float] = {}
    for j in jobs:
        s = _number(j, "stature_m")
        stature.setdefault(str(j.get("body", "")), s if s is not None else math.inf)
    return sorted(stature, key=lambda b: (stature[b], b))


def _job_label(job: Job) -> str:
    ground = job.get("ground") or ""
    return f"{job.get('clip', '')} / {job.get('body', '')}" + (f" / {ground}" if ground else "")


# ---------------------------------------------------------------------------------------------
# Plots (each returns a matplotlib Figure; :func:`figure_pngs` renders them)


def _strip_panel(ax: Any, jobs: Sequence[Job], key: str, rows: list[str],
                 row_of: Callable[[Job], str], colour_of: Callable[[Job], str],
                 colours: dict[str, Any]) -> None:
    """One dot per job on its row (spread across the row so equal values stay visible) and the
    tolerance as a dashed line; one scatter call per colour (a batch has thousands of jobs)."""
    index = {r: i for i, r in enumerate(rows)}
    tolerance, unit, label = TOLERANCES[key]
    count: dict[str, int] = {}
    dots: dict[str, tuple[list[float], list[float]]] = {}
    for j in jobs:
        value = _number(j, key)
        row = row_of(j)
        if value is None or row not in index:
            continue
        n = count[row] = count.get(row, 0) + 1
        spread = ((n * 0.618) % 1.0 - 0.5) * 0.6  # golden-ratio steps: even, no random generator
        xs, ys = dots.setdefault(colour_of(j), ([], []))
        xs.append(value)
        ys.append(index[row] + spread)
    for name, (xs, ys) in dots.items():
        ax.scatter(xs, ys, s=16, alpha=0.75, color=colours[name], edgecolors="none")
    ax.axvline(tolerance, color="#c53030", ls="--", lw=1)
    ax.set_yticks(range(len(rows)), rows)
    ax.set_ylim(len(rows) - 0.5, -0.5)
    ax.set_xlabel(f"{label} ({unit})")
    right = max(ax.get_xlim()[1], tolerance * 1.25)
    ax.set_xlim(-0.02 * right, right)  # a zero stays visible beside the axis
    ax.grid(axis="x", alpha=0.3)
    ax.hlines(np.arange(len(rows) - 1) + 0.5, *ax.get_xlim(), color="#e2e8f0", lw=0.8)


def _legend(fig: Figure, colours: dict[str, Any], title: str) -> None:
    if len(colours) < 2:
        return
    handles = [Line2D([], [], ls="none", marker="o", color=c, label=name or "(plane)")
               for name, c in colours.items()]
    fig.legend(handles=handles, title=title, loc="upper center", ncol=min(len(colours), 6),
               frameon=False, bbox_to_anchor=(0.5, 1.0))


def _colours(names: Sequence[str]) -> dict[str, Any]:
    return {n: PALETTE[i % len(PALETTE)] for i, n in enumerate(names)}


#: The figures plotted per body and per clip (floating too: a planted foot held above the ground
#: is the other way a foot goes wrong).
GROUP_PANELS = ("slide_max_mm", "penetration_max_mm", "floating_max_mm")


def plot_by_group(jobs: Sequence[Job], group: str) -> Figure:
    """Foot sliding, penetration and floating, one row per body (``group="body"``, small to tall, dots
    coloured by ground) or per clip (``group="clip"``, the clip with the worst job first, dots
    coloured by body)."""
    measured = _measured(jobs)
    worst: dict[str, float] = {}
    if group == "body":
        rows = _body_order(measured)
        colour_key = "ground"
    else:
        for j in measured:
            clip = str(j.get("clip", ""))
            worst[clip] = max(worst.get(clip, -1.0), badness(j)[0])
        rows = sorted(worst, key=lambda c: (-worst[c], c))[:MAX_CLIP_ROWS]
        colour_key = "body"
    names = (sorted({str(j.get("ground") or "") for j in measured}) if colour_key == "ground"
             else _body_order(measured))
    colours = _colours(names)
    height = 1.6 + 0.32 * len(rows) + (0.4 if len(colours) > 1 else 0.0)
    fig, axes = plt.subplots(1, len(GROUP_PANELS), figsize=(13, height), sharey=True,
                             squeeze=False)
    for ax, key in zip(axes[0], GROUP_PANELS, strict=False):
        _strip_panel(ax, measured, key, rows, lambda j: str(j.get(group, "")),
                     lambda j: str(j.get(colour_key) or ""), colours)
    if group == "clip" and len(worst) > len(rows):
        axes[0][0].set_title(f"the {len(rows)} clips with the worst jobs, of {len(worst)}",
                             fontsize=9, loc="left")
    _legend(fig, colours, colour_key)
    fig.tight_layout(rect=(0, 0, 1, 1 - 0.45 / height if len(colours) > 1 else 1))
    return fig


#: The panels of the stature plot: (record field, y-axis label).
STATURE_PANELS = (
    ("slide_max_mm", "foot sliding, max (mm/frame)"),
    ("penetration_max_mm", "penetration, max (mm)"),
    ("floating_max_mm", "floating, max (mm)"),
    ("constraint", "worst constraint error (mm)"),
    ("com_error_mm", "COM error, max (mm)"),
)


def plot_against_stature(jobs: Sequence[Job]) -> Figure:
    """The figures against the body's stature: one dot per job, each (clip, ground)'s jobs
    joined in stature order (thin grey), the median at each stature (bold). Panels without any
    figure (no constraints, no COM control) are left out."""
    measured = [j for j in _measured(jobs) if _number(j, "stature_m") is not None]
    panels = [(k, label) for k, label in STATURE_PANELS
              if any(_figure(j, k) is not None for j in measured)] or list(STATURE_PANELS[:2])
    columns = 2 if len(panels) in (2, 4) else min(len(panels), 3)
    lines = math.ceil(len(panels) / columns)
    fig, axes = plt.subplots(lines, columns, figsize=(4.2 * columns, 3.3 * lines), squeeze=False)
    for ax in axes.flat[len(panels):]:
        ax.set_visible(False)
    for ax, (key, label) in zip(axes.flat, panels, strict=False):
        series: dict[tuple[str, str], list[tuple[float, float]]] = {}
        at_stature: dict[float, list[float]] = {}
        for j in measured:
            value, stature = _figure(j, key), _number(j, "stature_m")
            if value is None or stature is None:
                continue
            series.setdefault((str(j.get("clip")), str(j.get("ground") or "")), []).append(
                (stature, value))
            at_stature.setdefault(round(stature, 4), []).append(value)
        alpha = min(0.7, max(0.12, 8.0 / max(len(series), 1)))  # many clips: fainter lines
        ax.add_collection(LineCollection([sorted(points) for points in series.values()],
                                         colors="#a0aec0", linewidths=0.8, alpha=alpha, zorder=1))
        every = [p for points in series.values() for p in points]
        if every:
            ax.scatter(*zip(*every, strict=False), s=9, color="#4a5568", alpha=min(0.6, 3 * alpha),
                       edgecolors="none", zorder=2)
        if at_stature:
            xs = sorted(at_stature)
            quartiles = np.array([np.percentile(at_stature[x], (25, 50, 75)) for x in xs])
            if len(every) > len(xs):  # a band only when a stature has several jobs
                ax.fill_between(xs, quartiles[:, 0], quartiles[:, 2], color="#2b6cb0",
                                alpha=0.18, lw=0, zorder=2.5)
            ax.plot(xs, quartiles[:, 1], "-o", color="#2b6cb0", lw=2, ms=5, zorder=3)
        ax.autoscale_view()
        if key in TOLERANCES:
            ax.axhline(TOLERANCES[key][0], color="#c53030", ls="--", lw=1, label="tolerance")
        top = max(ax.get_ylim()[1], TOLERANCES[key][0] * 1.25 if key in TOLERANCES else 0.0)
        ax.set_ylim(-0.02 * top, top)
        ax.set_xlabel("stature (m)")
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    handles = [Line2D([], [], color="#a0aec0", marker="o", mfc="#4a5568", mec="none", ms=3,
                          label="one clip (and ground) across bodies"),
               Line2D([], [], color="#2b6cb0", lw=2, marker="o", ms=5,
                          label="median at each stature"),
               Rectangle((0, 0), 1, 1, color="#2b6cb0", alpha=0.18,
                             label="middle half of the jobs (25-75 %)"),
               Line2D([], [], color="#c53030", ls="--", lw=1, label="tolerance")]
    fig.legend(handles=handles, loc="upper center", ncol=4, frameon=False, fontsize=9)
    fig.tight_layout(rect=(0, 0, 1, 1 - 0.35 / fig.get_figheight()))
    return fig


def _intervals(job: Job, foot: str) -> list[tuple[float, float]]:
    spans = (job.get("contacts") or {}).get(foot) or []
    return [(float(a), float(b)) for a, b in spans if b >= a]


def _same_contacts(a: Job, b: Job, tolerance_s: float = 0.05) -> bool:
    for foot in ("left", "right"):
        x, y = _intervals(a, foot), _intervals(b, foot)
        if len(x) != len(y) or any(abs(p - q) > tolerance_s
                                   for s, t in zip(x, y, strict=False) for p, q in zip(s, t, strict=False)):
            return False
    return True


def plot_contact_timeline(jobs: Sequence[Job]) -> Figure:
    """When each foot is planted, per clip: two lanes (left, right) drawn from the clip's first
    measured job (by body stature); the label says on how many of the clip's jobs the planted
    intervals agree within 50 ms (ground adaptation may shift them)."""
    by_clip: dict[str, list[Job]] = {}
    order = {b: i for i, b in enumerate(_body_order(jobs))}
    for j in sorted(_measured(jobs), key=lambda j: (order.get(str(j.get("body")), 0),
                                                    str(j.get("ground") or ""))):
        by_clip.setdefault(str(j.get("clip", "")), []).append(j)
    clips = sorted(by_clip)
    shown = clips[:MAX_TIMELINE_CLIPS]
    height = 1.2 + 0.62 * max(len(shown), 1)
    fig, ax = plt.subplots(figsize=(10, height))
    labels, end_s = [], 0.0
    for i, clip in enumerate(shown):
        first = by_clip[clip][0]
        agree = sum(_same_contacts(first, j) for j in by_clip[clip])
        for lane, foot in enumerate(("left", "right")):
            spans = _intervals(first, foot)
            y = i * 3 + lane
            ax.broken_barh([(a, max(b - a, 1e-3)) for a, b in spans], (y - 0.4, 0.8),
                           color=FOOT_COLOURS[foot])
            end_s = max([end_s] + [b for _, b in spans])
        duration = _number(first, "duration_s")
        if duration is not None:
            end_s = max(end_s, duration)
            ax.plot([duration, duration], [i * 3 - 0.5, i * 3 + 1.5], color="#1a202c", lw=1.2)
        n = len(by_clip[clip])
        agreement = f"same on all {n} jobs" if agree == n else f"same on {agree} of {n} jobs"
        labels.append((i * 3 + 0.5, f"{clip}\n{first.get('body')}: {agreement}"))
    ax.set_yticks([y for y, _ in labels], [text for _, text in labels], fontsize=8)
    ax.set_ylim(max(len(shown) * 3 - 1, 2) - 0.3, -0.7)
    ax.set_xlim(0.0, max(end_s, 1.0) * 1.02)
    ax.set_xlabel("time (s)")
    ax.set_axisbelow(True)  # the grid behind the bars: a bar reads as one piece
    ax.grid(axis="x", alpha=0.3)
    handles = [Rectangle((0, 0), 1, 1, color=c, label=f"{foot} foot planted")
               for foot, c in FOOT_COLOURS.items()]
    ax.legend(handles=handles, loc="lower right", fontsize=8, ncol=2,
              bbox_to_anchor=(1.0, 1.0), frameon=False)
    if len(clips) > len(shown):
        ax.set_title(f"the first {len(shown)} of {len(clips)} clips", fontsize=9, loc="left")
    fig.tight_layout()
    return fig


def figure_pngs(jobs: Sequence[Job]) -> dict[str, bytes]:
    """The report's plots as PNG files' bytes, by name (none when no job has figures):
    ``by_body``, ``by_clip``, ``stature``, ``contacts``."""
    if not _measured(jobs):
        return {}
    makers: dict[str, Callable[[], Figure]] = {
        "by_body": lambda: plot_by_group(jobs, "body"),
        "by_clip": lambda: plot_by_group(jobs, "clip"),
        "stature": lambda: plot_against_stature(jobs),
        "contacts": lambda: plot_contact_timeline(jobs),
    }
    pngs = {}
    # names are text, never math: a clip named "a $b$" would be parsed as math text, and fail
    with matplotlib.rc_context({"text.parse_math": False}):
        for name, make in makers.items():
            fig = make()
            try:
                buffer = io.BytesIO()
                fig.savefig(buffer, format="png", dpi=DPI)
                pngs[name] = buffer.getvalue()
            finally:
                plt.close(fig)  # a long batch makes many reports: free each figure
    return pngs


# ---------------------------------------------------------------------------------------------
# The page

CAPTIONS = {
    "by_body": "Foot sliding, penetration and floating per body (small to tall): one dot per job, "
               "coloured by ground; the dashed line is the tolerance.",
    "by_clip": "The same per clip, the clip with the worst job first (as in the table below); "
               "dots coloured by body.",
    "stature": "The figures against stature: each clip's jobs joined across bodies (grey), the "
               "median and the middle half of the jobs at each stature (blue), the tolerance "
               "dashed.",
    "contacts": "When each foot is planted, per clip (from its first job by stature; the label "
                "says on how many of the clip's jobs the intervals agree within 50 ms).",
}

STYLE = """
body { font: 14px/1.4 system-ui, sans-serif; margin: 1.5em; color: #1a202c; }
h1 { font-size: 1.4em; } h2 { font-size: 1.15em; margin-top: 1.6em; }
table { border-collapse: collapse; font-size: 12px; }
th, td { border: 1px solid #cbd5e0; padding: 2px 6px; text-align: right; white-space: nowrap; }
th { background: #edf2f7; position: sticky; top: 0; }
td.text { text-align: left; } td.bad { background: #fed7d7; font-weight: 600; }
tr.failed td { background: #fff5f5; } img { max-width: 100%; border: 1px solid #e2e8f0; }
.caption { color: #4a5568; margin: 0.2em 0 1em; }
"""

#: The columns of the jobs table: (header, record field); ``constraint`` is the worst one.
COLUMNS = (
    ("floating mm", "floating_max_mm"), ("penetration mm", "penetration_max_mm"),
    ("slide max mm/frame", "slide_max_mm"), ("slide mean mm/frame", "slide_mean_mm"),
    ("skate ratio", "foot_skate_ratio"), ("bone error m", "bone_error_m"),
    ("COM error mm", "com_error_mm"),
)


def _e(value: object) -> str:
    return html.escape(str(value), quote=True)


def _format(value: float | None, key: str) -> str:
    if value is None:
        return "—"
    if key == "bone_error_m":
        return f"{value:.1e}"
    if key == "foot_skate_ratio":
        return f"{value:.3f}"
    return f"{value:.2f}" if abs(value) < 1000 else f"{value:.0f}"


def _cell(value: float | None, key: str) -> str:
    bad = value is not None and key in TOLERANCES and value > TOLERANCES[key][0]
    return f'<td{" class=bad" if bad else ""}>{_format(value, key)}</td>'


def _links(job: Job) -> str:
    """Links to a job's outputs: their paths start at the batch folder, which holds the report."""
    return " ".join(f'<a href="{_e(urllib.parse.quote(str(p)))}">{_e(Path(str(p)).suffix[1:] or p)}</a>'
                    for p in job.get("outputs") or [])


def _jobs_table(jobs: Sequence[Job]) -> str:
    head = ["#", "clip", "body", "ground", "stature m", "frames", "status", "worst figure",
            "badness"] + [h for h, _ in COLUMNS] + ["worst constraint mm", "seconds", "files"]
    rows = ["<tr>" + "".join(f"<th>{_e(h)}</th>" for h in head) + "</tr>"]
    ranked = sorted(_measured(jobs), key=lambda j: (-badness(j)[0], _job_label(j)))
    for rank, j in enumerate(ranked, 1):
        score, key = badness(j)
        worst = worst_constraint(j)
        stature = _number(j, "stature_m")
        frames = j.get("frames")
        cells = [f"<td>{rank}</td>"]
        cells += [f'<td class=text>{_e(j.get(k) or "")}</td>' for k in ("clip", "body", "ground")]
        cells += [f"<td>{'—' if stature is None else f'{stature:.2f}'}</td>",
                  f"<td>{_e(frames if frames is not None else '—')}</td>",
                  f"<td class=text>{_e(j.get('status', ''))}</td>",
                  f"<td class=text>{_e(TOLERANCES[key][2] if key else '—')}</td>",
                  f'<td{" class=bad" if score > 1.0 else ""}>{score:.2f}</td>']
        cells += [_cell(_number(j, k), k) for _, k in COLUMNS]
        cells.append("<td>—</td>" if worst is None else
                     f'<td{" class=bad" if worst[1] > TOLERANCES["constraint"][0] else ""}>'
                     f"{_e(worst[0])}: {worst[1]:.2f}</td>")
        seconds = _number(j, "seconds")
        cells.append(f"<td>{'—' if seconds is None else f'{seconds:.2f}'}</td>")
        cells.append(f"<td class=text>{_links(j)}</td>")
        rows.append("<tr>" + "".join(cells) + "</tr>")
    return "<table>\n" + "\n".join(rows) + "\n</table>"


def _failed_list(jobs: Sequence[Job]) -> str:
    failed = sorted((j for j in jobs if j.get("status") == "failed"), key=_job_label)
    if not failed:
        return ""
    items = "\n".join(f"<tr class=failed><td class=text>{_e(j.get('clip', ''))}</td>"
                      f"<td class=text>{_e(j.get('body', ''))}</td>"
                      f"<td class=text>{_e(j.get('ground') or '')}</td>"
                      f"<td class=text>{_e(j.get('error') or '(no message)')}</td></tr>"
                      for j in failed)
    return (f"<h2>Failed jobs ({len(failed)})</h2>\n<table><tr><th>clip</th><th>body</th>"
            f"<th>ground</th><th>error</th></tr>\n{items}\n</table>")


def _tolerance_list() -> str:
    items = "".join(f"<li>{_e(label)}: {tol:g} {_e(unit)}</li>"
                    for tol, unit, label in TOLERANCES.values())
    skate = ("<li>foot-skate ratio (frames with a foot under 5 cm moving faster than 2.5 cm per "
             "30 Hz frame): shown, not ranked, since its fixed thresholds count a small body's "
             "low swing as skating</li>")
    return f"<ul>{items}{skate}</ul>"


def report_html(jobs: Sequence[Job]) -> str:
    """The report page for ``jobs`` (its links are the records' ``outputs``, relative to the
    folder the page is written in)."""
    statuses = [str(j.get("status", "")) for j in jobs]
    ok, skipped, failed = (statuses.count(s) for s in ("ok", "skipped", "failed"))
    seconds = sum(_number(j, "seconds") or 0.0 for j in jobs)
    over = sum(badness(j)[0] > 1.0 for j in _measured(jobs))
    clips = len({j.get("clip") for j in jobs})
    bodies = len({j.get("body") for j in jobs})
    grounds = len({j.get("ground") or "" for j in jobs})
    parts = [
        "<!DOCTYPE html>\n<html lang=en><head><meta charset=utf-8>",
        "<title>ecs-anim batch report</title>", f"<style>{STYLE}</style></head><body>",
        "<h1>ecs-anim batch report</h1>",
        (f"<p>{len(jobs)} jobs over {clips} clips, {bodies} bodies and {grounds} grounds: "
         f"<b>{ok} ok</b>, {skipped} skipped (done by an earlier run), "
         f"<b{' style=color:#c53030' if failed else ''}>{failed} failed</b>; "
         f"{over} over a tolerance; {seconds:.1f} s of job time.</p>"),
        _failed_list(jobs),
    ]
    pngs = figure_pngs(jobs)
    titles = {"by_body": "Per body", "by_clip": "Per clip", "stature": "Against stature",
              "contacts": "Contact timeline"}
    for name, png in pngs.items():
        data = base64.b64encode(png).decode("ascii")
        parts.append(f"<h2>{titles[name]}</h2>\n<img alt='{_e(titles[name])}' "
                     f"src='data:image/png;base64,{data}'>\n"
                     f"<p class=caption>{_e(CAPTIONS[name])}</p>")
    if _measured(jobs):
        parts += ["<h2>Jobs, the worst first</h2>",
                  ("<p class=caption>badness = the job's largest figure over its tolerance "
                   "(1.0 is at the limit); marked cells are over their tolerance:</p>"),
                  _tolerance_list(), _jobs_table(jobs)]
    parts.append("</body></html>\n")
    return "\n".join(p for p in parts if p)
