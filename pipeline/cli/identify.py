"""``pipeline identify``: the dynamic-identification sub-app (pipeline/identify/cli.py)."""

from __future__ import annotations

from pipeline.cli.root import app
from pipeline.identify.cli import identify_app

app.add_typer(identify_app, name="identify")
