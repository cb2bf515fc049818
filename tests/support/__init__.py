"""What the tests share: plain helpers, harnesses and reference implementations (fixtures are in conftest.py)."""

from __future__ import annotations

from pathlib import Path

# The repository root, whatever folder a test module lives in.
REPO = Path(__file__).resolve().parents[2]
