"""The README's screenshot of the teach page.

    python -m tests.teach.screenshot docs/img/teach.png

A ur5 page in headless Chromium, the target dragged by the scripted client in
small steps, the solved arm and the FK readout of the last step.
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import numpy as np

from pipeline import transforms as tf
from pipeline.model.dh import forward_kinematics
from pipeline.teach.wire import PageClient
from tests.teach.chromium import Chromium
from tests.teach.conftest import start_server

TAUGHT_Q = [0.5, -1.3, 1.4, -0.9, -1.1, 0.4]


def main(out: Path) -> None:
    server = start_server("ur5")
    try:
        with tempfile.TemporaryDirectory() as tmp, Chromium(Path(tmp) / "profile") as browser:
            browser.navigate(server.url)
            if not browser.wait_for("document.body.innerText.includes('position error')"):
                raise SystemExit("the page never showed its readout")
            spec = server.session.spec
            start = server.state.q.copy()
            with PageClient(server.url) as client:
                client.pump_until(lambda c: spec.joint_names[0] in c.gui_label.values())
                # a drag: the target moves in 20 steps, each answered before the next
                for s in np.linspace(0.05, 1.0, 20):
                    target = forward_kinematics(spec, start + s * (np.array(TAUGHT_Q) - start))
                    n = len(client.received)
                    client.move_target(target[:3, 3], tf.quat_wxyz(target[:3, :3]))
                    client.pump_until(lambda c, n=n: len(c.received) > n)
            if not browser.wait_for("document.body.innerText.includes('Solved')"):
                raise SystemExit("the page never showed the solved target")
            # close viser's "software WebGL" notice (headless has no GPU)
            browser.evaluate(
                "document.querySelectorAll('.mantine-Notification-closeButton')"
                ".forEach(b => b.click())"
            )
            browser.wait_for("!document.body.innerText.includes('Software WebGL')", timeout_s=5)
            out.write_bytes(browser.screenshot())
    finally:
        server.close()
    print(f"wrote {out}")


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else Path("docs/img/teach.png"))
