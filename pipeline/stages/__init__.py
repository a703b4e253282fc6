"""Stages: thin glue that runs one CLI command from the pieces below it."""

from __future__ import annotations
