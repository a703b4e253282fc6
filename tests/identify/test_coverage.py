"""Issue 27 item 4: do identification's standard errors hold? On 20 drawn
``paper-realistic`` plants whose true parameters are known (``benches/identify_coverage.py``,
the same code), the share of base-parameter estimates within +-2 Newey-West standard errors
of the truth.

The target is >= 90 %; measured 89.7 % (docs/identify.md, "Standard errors"): MISSED, so
this test guards the measured level, not the target: at least 88 %. It fails when the bias
fixes go (86.3 % without the filtered Coulomb columns and the zero-order-hold alignment) or
the errors shrink (the textbook error: 61 %). Deterministic: seeded plants, noise and
excitations, one BLAS thread."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

BENCH = Path(__file__).resolve().parents[2] / "benches" / "identify_coverage.py"
PLANTS = 20
GUARD = 0.88


@pytest.mark.slow
def test_newey_west_coverage_on_20_drawn_plants_stays_at_the_measured_level(
    tmp_path: Path,
) -> None:
    spec = importlib.util.spec_from_file_location("identify_coverage", BENCH)
    assert spec is not None and spec.loader is not None
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    rows = [bench.one_plant(seed, periods=1, tmp=tmp_path) for seed in range(PLANTS)]
    total = sum(r["parameters"] for r in rows)
    hac = sum(r["within_hac"] for r in rows) / total
    iid = sum(r["within_iid"] for r in rows) / total
    assert hac >= GUARD, f"Newey-West coverage {hac:.1%} < {GUARD:.0%}"
    assert iid < 0.8  # the textbook error is too small here: the check tells them apart
