"""The Khronos glTF validator (npm ``gltf-validator`` in tests/gltf_validator, run with node):
required where CI runs (CI=true), otherwise skipped, saying how to install it."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
from pathlib import Path

import pytest

from conftest import REPO

VALIDATOR_DIR = REPO / "tests" / "gltf_validator"


def validate(paths: list[Path]) -> dict[str, dict]:
    """The Khronos validator's report summary per file."""
    node = shutil.which("node")
    installed = (VALIDATOR_DIR / "node_modules" / "gltf-validator").is_dir()
    if node is None or not installed:
        why = (f"the glTF validator is not installed (node: {node or 'missing'}; run "
               f"`npm ci --prefix {VALIDATOR_DIR.relative_to(REPO)}`)")
        if os.environ.get("CI") == "true":
            pytest.fail(why)
        pytest.skip(why)
    done = subprocess.run([node, str(VALIDATOR_DIR / "validate.cjs"), *map(str, paths)],
                          capture_output=True, text=True, timeout=300, check=False)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout)


def assert_valid(paths: list[Path]) -> None:
    """Every file of ``paths`` passes the validator with no error and no warning."""
    reports = validate(paths)
    for path in paths:
        report = reports[str(path)]
        found = [(m["code"], m.get("pointer")) for m in report["messages"] if m["severity"] <= 1]
        assert (report["numErrors"], report["numWarnings"]) == (0, 0), (path.name, found[:5])
