"""A batch's progress on stderr: jobs done, failures and time left."""

from __future__ import annotations

import sys
import time
from typing import Any


class Progress:
    """Jobs done, failures and time left: a tqdm bar on a terminal, else one plain line a job
    (``[3/12] walk/child_bumps ok 0.41 s; 0 failed; about 4 s left``) on stderr."""

    def __init__(self, total: int, stream: Any = None):
        self.total, self.done, self.failed = total, 0, 0
        self.stream = stream or sys.stderr
        self.start = time.perf_counter()
        self.bar = None
        if total and getattr(self.stream, "isatty", lambda: False)():
            from tqdm import tqdm

            self.bar = tqdm(total=total, unit="job", file=self.stream, dynamic_ncols=True)

    def update(self, stem: str, record: dict[str, Any]) -> None:
        self.done += 1
        self.failed += record["status"] == "failed"
        if record["status"] == "failed":
            self.write(f"error: {stem}: {record['error']}")
        if self.bar is not None:
            self.bar.set_postfix(failed=self.failed, refresh=False)
            self.bar.update(1)
            return
        elapsed = time.perf_counter() - self.start
        left = elapsed / self.done * (self.total - self.done)
        self.write(f"[{self.done}/{self.total}] {stem} {record['status']} {record['seconds']:.2f} s; "
                   f"{self.failed} failed; about {left:.0f} s left")

    def write(self, line: str) -> None:
        if self.bar is not None:
            self.bar.write(line, file=self.stream)
        else:
            print(line, file=self.stream, flush=True)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
