"""Memory of reading long bags: peak RSS of ``read_recording`` vs bag length.

Writes paper-like episodes (UR5, 1 kHz, every topic of a recording) of increasing length
with the project's writer, reads each in a fresh subprocess and prints one JSON object:
per length the bag size, the peak RSS of the reading process, the size of the frames it
returns, and the fit RSS = a + b * minutes with its extrapolation to one hour. The reader
streams (one chunk in memory at a time, tests/log/test_streaming_memory.py); what grows is
the decoded frames, so the growth per minute should be close to the frames' bytes per
minute.

Usage: python benches/long_bag.py [--minutes 1 3]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

CHILD = """
import json, resource, sys
from pipeline.log.reader import read_recording
rec = read_recording(sys.argv[1])
frames = rec.samples.estimated_size() + rec.controller_states.estimated_size()
print(json.dumps({"peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
                  "frames_mb": frames / 2**20, "rows": rec.samples.height}))
"""


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=float, nargs="+", default=[1.0, 3.0])
    args = parser.parse_args()
    from pipeline.log import bag
    from pipeline.robots import load_spec
    from tests.log.test_writer import analytic_episode, episode_metadata

    spec = load_spec("ur5")
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for minutes in args.minutes:
            result, planned = analytic_episode(spec, n_steps=round(minutes * 60_000))
            summary = bag.write_episode_bag(
                Path(tmp) / f"m{minutes}",
                spec=spec,
                result=result,
                planned=planned,
                metadata=episode_metadata(),
            )
            del result, planned
            out = subprocess.run(
                [sys.executable, "-c", CHILD, str(summary.path)],
                capture_output=True,
                text=True,
                check=True,
                cwd=REPO,
            )
            row = json.loads(out.stdout)
            row |= {"minutes": minutes, "bag_mb": summary.size_bytes / 2**20}
            rows.append({k: round(v, 1) if isinstance(v, float) else v for k, v in row.items()})
    (m0, r0), (m1, r1) = [(r["minutes"], r["peak_rss_mb"]) for r in rows[:1] + rows[-1:]]
    per_min = (r1 - r0) / (m1 - m0)
    frames_per_min = (rows[-1]["frames_mb"] - rows[0]["frames_mb"]) / (m1 - m0)
    print(
        json.dumps(
            {
                "bench": "long_bag",
                "runs": rows,
                "rss_mb_per_minute": round(per_min, 1),
                "frames_mb_per_minute": round(frames_per_min, 1),
                "one_hour_rss_mb_extrapolated": round(r0 + per_min * (60 - m0)),
            },
            indent=2,
        )
    )


if __name__ == "__main__":
    main()
