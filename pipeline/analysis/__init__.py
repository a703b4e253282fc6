"""Polars frames from recordings, and tracking metrics per episode and joint."""

from __future__ import annotations
