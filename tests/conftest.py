"""Shared fixtures: the real captured clips in ../shared/mocap (never copied into the repo)."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
MOCAP_DIR = Path(os.environ.get("ECS_ANIM_MOCAP", REPO.parent / "shared" / "mocap"))
MOTIONS_DIR = REPO / "scenarios" / "motions"


def mocap_files(pattern: str = "*.bvh") -> list[Path]:
    return sorted(MOCAP_DIR.glob(pattern)) if MOCAP_DIR.is_dir() else []


def require_mocap() -> None:
    if not MOCAP_DIR.is_dir():
        pytest.skip(f"real captured clips not found at {MOCAP_DIR} (they live in ../shared/mocap; "
                    "CI always has them)")


def mocap_params(pattern: str = "*.bvh") -> list[object]:
    files = mocap_files(pattern)
    if not files:
        return [pytest.param(None, marks=pytest.mark.skip(
            reason=f"real captured clips not found at {MOCAP_DIR} (../shared/mocap)"))]
    return [pytest.param(f, id=f.name) for f in files]
