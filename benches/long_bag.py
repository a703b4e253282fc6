"""Memory of long bags: peak RSS of the report's per-recording path vs bag length.

Writes paper-like episodes (UR5, 1 kHz, every topic of a recording) of increasing length
with the project's writer (a long one in pieces of ``--piece-minutes``, as a split bag:
one storage file per piece in one rosbag2 folder, so writing never holds an hour of
samples), then, per length, in a fresh subprocess: reads it and applies the protocol and
the metrics exactly as ``pipeline report`` does per recording (``read_all`` with the
report's measuring sink), and prints one JSON object with the peak RSS of each run.
Recordings above ``STREAM_ABOVE_BYTES`` are read in windows (pipeline/log/windowed.py);
``--windowed`` forces that on every length, for a like-for-like line. With ``--report``,
``pipeline report`` also runs end to end on the longest bag (wall time, peak RSS of it and
its children, output sizes).

Usage: python benches/long_bag.py [--minutes 1 10 60] [--windowed] [--report]
"""

from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

CHILD = """
import json, sys, time
from pathlib import Path
from pipeline.log.reader import ReadOptions
from pipeline.analysis.measure import Measured
from pipeline.stages.report import read_all
m = Measured()
options = ReadOptions(stream_above_bytes=0) if sys.argv[2] == "1" else ReadOptions()
t = time.perf_counter()
[rec], _ = read_all(Path(sys.argv[1]), skip_bad=False, options=options, measure=m.add, sink=m)
# VmHWM, not ru_maxrss: Linux carries the parent's peak over fork + exec into ru_maxrss
hwm = next(int(l.split()[1]) for l in open("/proc/self/status") if l.startswith("VmHWM:"))
print(json.dumps({"peak_rss_mb": hwm / 1024,
                  "wall_s": time.perf_counter() - t, "windows": rec.windows,
                  "decimation": rec.decimation,
                  "controller_samples": int(m.rows[rec.episode]["controller_samples"][0]),
                  "metrics_rows": m.metrics[rec.episode].height}))
"""


def write_long_bag(folder: Path, *, minutes: float, piece_minutes: float) -> int:
    """A ``minutes``-long episode in ``folder`` (a split bag); returns its size [bytes]."""
    import yaml

    from pipeline.log import bag, rosbag2
    from pipeline.robots import load_spec
    from tests.log.test_writer import DT_NS, analytic_episode, episode_metadata

    spec = load_spec("ur5")
    total = round(minutes * 60_000)
    piece = round(piece_minutes * 60_000)
    folder.mkdir(parents=True)
    start = 0
    k = 0
    while start < total:
        steps = min(piece, total - start)
        result, planned = analytic_episode(spec, n_steps=steps, t0_ns=start * DT_NS)
        part = folder.parent / f".{folder.name}.piece"
        summary = bag.write_episode_bag(
            part, spec=spec, result=result, planned=planned, metadata=episode_metadata()
        )
        del result, planned
        summary.mcap_path.rename(folder / f"{folder.name}_{k:03d}.mcap")
        if k == 0:
            info = yaml.safe_load((part / rosbag2.METADATA_FILE).read_text(encoding="utf-8"))
        shutil.rmtree(part)
        start += steps
        k += 1
    # one rosbag2 folder listing every piece (counts and duration are the first piece's)
    info["rosbag2_bagfile_information"]["relative_file_paths"] = [
        f"{folder.name}_{i:03d}.mcap" for i in range(k)
    ]
    (folder / rosbag2.METADATA_FILE).write_text(yaml.safe_dump(info), encoding="utf-8")
    return sum(p.stat().st_size for p in folder.iterdir())


# Runs the command in a fresh, small process and prints the peak RSS of its children: a
# child's ru_maxrss starts from its parent's RSS at fork (Linux), and this script's own RSS
# is large after writing an hour of samples.
WRAPPER = """
import resource, subprocess, sys
subprocess.run(sys.argv[1:], check=True, capture_output=True)
print(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss)
"""


def report_end_to_end(recordings: Path, out: Path) -> dict[str, float]:
    """``pipeline report`` on ``recordings``: wall time, peak RSS (it and its children)."""
    t = time.perf_counter()
    run = subprocess.run(
        [
            sys.executable,
            "-c",
            WRAPPER,
            str(Path(sys.executable).with_name("pipeline")),
            "report",
            "--recordings",
            str(recordings),
            "--out",
            str(out),
        ],
        check=True,
        capture_output=True,
        text=True,
        cwd=REPO,
    )
    wall = time.perf_counter() - t
    peak_kb = int(run.stdout.split()[-1])
    sizes = {p.relative_to(out).as_posix(): p.stat().st_size for p in out.rglob("*") if p.is_file()}
    return {
        "wall_s": round(wall, 1),
        "peak_rss_mb": round(peak_kb / 1024, 1),
        "outputs_mb": round(sum(sizes.values()) / 2**20, 2),
        "rrd_mb": round(sizes.get("recording.rrd", 0) / 2**20, 2),
        "report_md_kb": round(sizes.get("report.md", 0) / 1024, 1),
        "csv_mb": round(sum(v for k, v in sizes.items() if k.endswith(".csv")) / 2**20, 2),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=float, nargs="+", default=[1.0, 10.0, 60.0])
    parser.add_argument("--piece-minutes", type=float, default=5.0)
    parser.add_argument("--windowed", action="store_true", help="read every length in windows")
    parser.add_argument("--report", action="store_true", help="pipeline report on the longest")
    args = parser.parse_args()
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for minutes in args.minutes:
            recordings = Path(tmp) / f"m{minutes:g}"
            t = time.perf_counter()
            size = write_long_bag(
                recordings / "ep", minutes=minutes, piece_minutes=args.piece_minutes
            )
            write_s = time.perf_counter() - t
            out = subprocess.run(
                [sys.executable, "-c", CHILD, str(recordings), "1" if args.windowed else "0"],
                capture_output=True,
                text=True,
                check=False,
                cwd=REPO,
            )
            if out.returncode:
                sys.exit(f"reading the {minutes:g}-minute bag failed:\n{out.stderr}")
            row = json.loads(out.stdout)
            row |= {"minutes": minutes, "bag_mb": size / 2**20, "write_s": write_s}
            rows.append({k: round(v, 1) if isinstance(v, float) else v for k, v in row.items()})
            if args.report and minutes == max(args.minutes):
                rows[-1]["pipeline_report"] = report_end_to_end(recordings, Path(tmp) / "out")
            shutil.rmtree(recordings)
    (m0, r0), (m1, r1) = [(r["minutes"], r["peak_rss_mb"]) for r in rows[:1] + rows[-1:]]
    per_min = (r1 - r0) / (m1 - m0) if m1 != m0 else 0.0
    print(
        json.dumps(
            {
                "bench": "long_bag",
                "windowed_forced": args.windowed,
                "runs": rows,
                "rss_mb_per_minute": round(per_min, 2),
            },
            indent=2,
        )
    )


if __name__ == "__main__":
    main()
