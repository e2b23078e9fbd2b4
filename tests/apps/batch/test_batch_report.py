"""The batch report (issue 15 item 2): report.html with non-blank plots (checked by pixels), the
worst jobs first with their files linked, failed jobs with their one-line error.

Records follow the job-record contract (metrics.json's ``jobs``). Most tests build them by hand;
one plays real clips (scenarios/motions) through the same pipeline ``ecs-anim run`` uses."""

from __future__ import annotations

import re

import numpy as np
import pytest

from conftest import MOTIONS_DIR
from ecs_anim.apps.batch.report import badness, figure_pngs, report_html, write_report
from ecs_anim.core.ground import Plane
from ecs_anim.runtime import metrics
from support.images import decode_png, embedded_pngs, ink


def record(clip, body, stature_m, ground="", status="ok", error="", slide=0.2, penetration=0.1,
           floating=0.3, skate=0.01, constraints=None, com=None, contacts=None, frames=90):
    """One job record as contract 3 gives it (failed jobs carry no figures)."""
    ok = status != "failed"
    suffix = f"_{ground}" if ground else ""
    return {
        "clip": clip, "body": body, "ground": ground, "stature_m": stature_m, "frames": frames,
        "status": status, "error": error,
        "slide_max_mm": slide if ok else None, "slide_mean_mm": slide / 3 if ok else None,
        "penetration_max_mm": penetration if ok else None,
        "floating_max_mm": floating if ok else None,
        "bone_error_m": 2e-9 if ok else None, "com_error_mm": com,
        "foot_skate_ratio": skate if ok else None, "seconds": 0.4,
        "outputs": [f"{clip}/{body}{suffix}.bvh", f"{clip}/{body}{suffix}.npz"] if ok else [],
        "constraint_errors_mm": constraints or {},
        "contacts": contacts if contacts is not None else
        {"left": [[0.0, 0.9], [1.9, 2.9]], "right": [[0.5, 1.4], [2.4, 3.0]]},
    }


def hand_jobs():
    """3 clips × 3 bodies × 2 grounds; one job slides badly, one clip failed to import."""
    jobs = []
    bodies = (("child", 1.20), ("adult_male", 1.75), ("tall", 2.00))
    for c, clip in enumerate(("walk", "dance", "kick")):
        for b, (body, stature) in enumerate(bodies):
            for ground in ("", "stairs"):
                jobs.append(record(clip, body, stature, ground, slide=0.1 + 0.05 * b + 0.1 * c,
                                   penetration=0.2 * b, constraints={"reach": 1.0 + b}))
    jobs[6]["slide_max_mm"] = 6.5  # dance / child / plane: the worst job
    jobs.append(record("broken", "child", 1.20, status="failed",
                       error="broken.bvh:3: expected a number, found 'x1'"))
    jobs.append(record("broken", "tall", 2.00, status="failed",
                       error="broken.bvh:3: expected a number, found 'x1'"))
    jobs[0]["status"] = "skipped"
    return jobs


def test_every_plot_is_drawn_with_data():
    pngs = figure_pngs(hand_jobs())
    assert set(pngs) == {"by_body", "by_clip", "stature", "contacts"}
    for name, png in pngs.items():
        pixels = decode_png(png)
        assert pixels.shape[0] > 200 and pixels.shape[1] > 400, name
        amount = ink(pixels)
        assert 0.02 < amount["drawn"] < 0.6, (name, amount)  # neither blank nor a filled block
        assert amount["coloured"] > 0.001, (name, amount)  # dots or bars, not only axes


def test_contact_timeline_bars_are_where_the_feet_are_planted():
    """The left foot's bar covers its planted second and not the gap; checked on the pixels of
    a column through the lanes."""
    jobs = [record("walk", "adult_male", 1.75,
                   contacts={"left": [[0.0, 1.0], [3.0, 4.0]], "right": [[2.0, 4.0]]})]
    pixels = decode_png(figure_pngs(jobs)["contacts"])[..., :3]
    blue = np.all(np.abs(pixels - np.array([0x2B, 0x6C, 0xB0]) / 255) < 0.05, axis=-1)
    orange = np.all(np.abs(pixels - np.array([0xC0, 0x56, 0x21]) / 255) < 0.05, axis=-1)
    # Along the pixel row through each lane (the row with the most of its colour; the legend's
    # swatches are shorter): two blue runs (0-1 s, 3-4 s) with a gap, one orange run (2-4 s).
    def runs(mask):
        columns = np.nonzero(mask[np.argmax(mask.sum(axis=1))])[0]
        return [r for r in np.split(columns, np.nonzero(np.diff(columns) > 1)[0] + 1)
                if r.size > 5]

    big, orange_runs = runs(blue), runs(orange)
    assert len(big) == 2, [r.size for r in big]
    assert len(orange_runs) == 1, [r.size for r in orange_runs]
    second = big[0].size  # pixels per second of the time axis
    assert big[1][0] - big[0][-1] == pytest.approx(2 * second, rel=0.1)  # the 1-3 s gap
    assert orange_runs[0][0] - big[0][0] == pytest.approx(2 * second, rel=0.1)  # right from 2 s
    assert orange_runs[0].size == pytest.approx(2 * second, rel=0.1)  # for 2 s


def test_worst_job_first_and_failed_jobs_listed_with_their_error(tmp_path):
    jobs = hand_jobs()
    out = tmp_path / "report.html"
    write_report(out, jobs)
    page = out.read_text("utf-8")
    assert [p for p in tmp_path.iterdir()] == [out]  # one file: plots embedded, no temporary left
    assert len(embedded_pngs(page)) == 4
    table = page[page.index("Jobs, the worst first"):]
    first_row = table.split("<tr>")[2]
    assert ">dance<" in first_row and ">child<" in first_row and "6.50" in first_row
    assert 'href="dance/child.bvh"' in first_row and 'href="dance/child.npz"' in first_row
    ranked = sorted((j for j in jobs if j["status"] != "failed"), key=lambda j: -badness(j)[0])
    worst, worst_key = badness(ranked[0])
    assert worst == pytest.approx(6.5 / metrics.SLIDE_EVENT_MM) and worst_key == "slide_max_mm"
    failed = page[page.index("Failed jobs (2)"):page.index("Per body")]
    assert failed.count("broken.bvh:3: expected a number, found &#x27;x1&#x27;") == 2
    assert "broken" not in table  # failed jobs are not ranked among the measured ones
    assert "17 ok</b>, 1 skipped" in page and "2 failed" in page


def test_names_are_escaped_and_links_quoted(tmp_path):
    job = record("a<b>&c", "body one", 1.7, constraints={"<x>": 50.0})
    page = report_html([job])
    assert "<b>&amp;c" not in page and "a&lt;b&gt;&amp;c" in page
    assert 'href="a%3Cb%3E%26c/body%20one.bvh"' in page
    assert "&lt;x&gt;: 50.00" in page  # and over the 10 mm tolerance:
    assert re.search(r"<td class=bad>&lt;x&gt;: 50.00</td>", page)


def test_all_failed_or_no_jobs_still_writes_a_report(tmp_path):
    out = tmp_path / "report.html"
    write_report(out, [record("x", "child", 1.2, status="failed", error="x.bvh: not found")])
    page = out.read_text("utf-8")
    assert "x.bvh: not found" in page and not embedded_pngs(page)
    write_report(out, [])  # rewritten whole
    assert "0 jobs" in out.read_text("utf-8")


def test_a_missing_figure_is_a_dash_not_a_crash():
    """No COM control (null), no constraints, a NaN figure: the report shows dashes and plots
    the rest."""
    job = record("walk", "child", 1.2, com=None)
    job["floating_max_mm"] = float("nan")
    del job["contacts"]
    pngs = figure_pngs([job, record("walk", "tall", 2.0, com=3.0)])
    assert all(ink(decode_png(p))["drawn"] > 0.02 for p in pngs.values())
    page = report_html([job])
    assert page.count("<td>—</td>") >= 3  # floating, COM, worst constraint


# ---------------------------------------------------------------------------------------------
# From real runs: the batch's own jobs (ecs_anim.apps.batch.jobs.run_job), records as metrics.json holds.

GROUNDS = {"": "{type: plane}", "slope": "{type: slope, grade_x: 0.08}"}


def real_jobs(tmp_path, seconds=2.0):
    from ecs_anim.apps.batch.jobs import import_clip, run_job
    from ecs_anim.apps.batch.plan import Job, NamedGround
    from ecs_anim.apps.batch.plan_parts import body_from_text, load_grounds

    (tmp_path / "grounds.yaml").write_text("grounds:\n" + "".join(
        f"  {name}: {spec}\n" for name, spec in GROUNDS.items() if name))
    grounds = [NamedGround("", Plane()), *load_grounds(tmp_path / "grounds.yaml")]
    jobs = []
    for clip in ("walk", "dance"):
        path = MOTIONS_DIR / f"{clip}.bvh"
        motion = import_clip(path)
        for body in ("child", "tall"):
            for ground in grounds:
                job = Job(str(path), clip, body_from_text(body), ground, ("bvh",), seconds)
                jobs.append(run_job(job, motion).record)
    return jobs


def test_report_from_real_runs(tmp_path):
    jobs = real_jobs(tmp_path)
    walk = [j for j in jobs if j["clip"] == "walk"]
    assert all(len(j["contacts"]["left"]) >= 2 for j in walk)  # a walk plants each foot again
    # the job's simulated length, which the contact timeline marks as the clip's end
    simulated_s = [j["duration_s"] for j in jobs]  # simulated, not wall-clock, seconds
    assert all(s == pytest.approx(j["frames"] / 30.0) == pytest.approx(2.0)
               for s, j in zip(simulated_s, jobs, strict=False))
    assert all(b <= s for s, j in zip(simulated_s, jobs, strict=False) for side in j["contacts"].values()
               for _, b in side)
    without_end = [{k: v for k, v in j.items() if k != "duration_s"} for j in jobs]
    with_end_pngs, without_end_pngs = (embedded_pngs(report_html(js)) for js in (jobs, without_end))
    assert [a == b for a, b in zip(with_end_pngs, without_end_pngs, strict=False)].count(False) == 1  # the timeline
    out = tmp_path / "batch" / "report.html"
    write_report(out, jobs)
    page = out.read_text("utf-8")
    pngs = embedded_pngs(page)
    assert len(pngs) == 4
    for png in pngs:
        amount = ink(decode_png(png))
        assert 0.02 < amount["drawn"] < 0.6 and amount["coloured"] > 0.001, amount
    worst = max(badness(j)[0] for j in jobs)
    first_row = page[page.index("Jobs, the worst first"):].split("<tr>")[2]
    # The first row is a job of the largest badness (several may share it).
    assert any(f">{j['clip']}<" in first_row and f">{j['body']}<" in first_row
               for j in jobs if badness(j)[0] == worst)
    assert f"{worst:.2f}" in first_row
