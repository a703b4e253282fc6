"""``pipeline identify``: the dynamic-identification sub-app (pipeline/cli/identify_app.py)."""

from __future__ import annotations

from pipeline.cli.identify_app import identify_app
from pipeline.cli.root import app

app.add_typer(identify_app, name="identify")
