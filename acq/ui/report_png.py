"""The report PNG of an identification (``<session>.report.png``), drawn once its result and catalogue row stand."""

from __future__ import annotations

import sys

from acq.offline.analyze import SessionResult, report_not_drawn
from acq.recording.storage import atomic_path
from acqcore.errors import StorageError


def draw_report(done: SessionResult) -> SessionResult:
    """Draw ``<session>.report.png`` of an identification already written (nothing when no report was asked for).

    A picture that fails is not a failed identification: the failure becomes a note on the result
    (:func:`acq.offline.analyze.report_not_drawn`) and one line on stderr; the returned result then has no report
    path.
    """
    if done.report_path is None:
        return done
    try:
        from acq.ui.plots import render_report_png  # Qt only when a picture is drawn

        with atomic_path(done.report_path) as tmp_png:
            render_report_png(done.result.figures, tmp_png, values=done.json_dict,
                              title=f"{done.session.meta.joint} · {done.session.path.name}")
    except StorageError:
        raise  # a write that failed (disk full, I/O error) is a failure, named by the file
    except Exception as e:  # noqa: BLE001 — whatever the plotting stack does, the identification stands
        why = f"{type(e).__name__}: {e}"
        noted = report_not_drawn(done, why)
        sys.stderr.write(f"acq: {done.report_path}: report not drawn ({why}); the result stands in {done.json_path}\n")
        return noted
    return done
