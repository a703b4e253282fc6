"""Interactive IK in the browser: ``pipeline teach ROBOT`` (a local viser page).

:mod:`pipeline.teach.session` computes (IK on a target, FK on joints, checks),
:mod:`pipeline.teach.goal` writes a taught goal into a params file,
:mod:`pipeline.teach.server` draws it all on the page and wires its events.
"""

from __future__ import annotations
