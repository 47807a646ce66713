"""Suite-wide settings: hypothesis runs derandomised on CI (the same examples every run, so a
red CI is a real regression), randomised on a developer's machine (new examples each run)."""

from __future__ import annotations

import os

from hypothesis import settings

settings.register_profile("ci", derandomize=True, print_blob=True)
if os.environ.get("CI"):
    settings.load_profile("ci")
