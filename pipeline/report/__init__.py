"""Report outputs: metrics.json + plot CSVs, matplotlib figures, Markdown, Rerun .rrd."""

from __future__ import annotations
