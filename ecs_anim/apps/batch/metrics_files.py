"""A batch's ``metrics.json`` and ``metrics.csv``: one record (row) per job."""

from __future__ import annotations

import csv
import io
import json
import math
from pathlib import Path
from typing import Any

from ecs_anim.apps.batch.job_hash import project_version

#: The scalar columns of ``metrics.csv``, in order (then ``constraint:<name>_mm``).
CSV_FIELDS = ("clip", "body", "ground", "stature_m", "frames", "status", "error", "slide_max_mm",
              "slide_mean_mm", "penetration_max_mm", "floating_max_mm", "overlap_max_mm",
              "bone_error_m", "com_error_mm", "foot_skate_ratio", "seconds")


def json_safe(value: Any) -> Any:
    from ecs_anim.apps.cli.args import json_safe as safe

    return safe(value)


def write_metrics(out: Path, records: list[dict[str, Any]], seconds: float) -> None:
    """``metrics.json`` ({"jobs", "version", "seconds"}) and ``metrics.csv`` (the scalar fields,
    then one ``constraint:<name>_mm`` column per constraint name, in first-seen order)."""
    from ecs_anim.core.files import atomic_output

    body = {"jobs": records, "version": project_version(), "seconds": round(seconds, 3)}
    with atomic_output(out / "metrics.json", force=True) as f:
        f.write(json.dumps(json_safe(body), indent=1, allow_nan=False).encode("utf-8"))
    names: list[str] = []
    for record in records:
        names += [n for n in record["constraint_errors_mm"] if n not in names]
    text = io.StringIO()
    writer = csv.writer(text, lineterminator="\n")
    writer.writerow([*CSV_FIELDS, *(f"constraint:{n}_mm" for n in names)])
    for record in records:
        values = [record[k] for k in CSV_FIELDS] + [record["constraint_errors_mm"].get(n) for n in names]
        writer.writerow(["" if v is None or (isinstance(v, float) and not math.isfinite(v)) else v
                         for v in values])
    with atomic_output(out / "metrics.csv", force=True) as f:
        f.write(text.getvalue().encode("utf-8"))
