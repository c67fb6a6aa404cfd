"""The monitor's raw window files (acq.monitoring.monitor_windows): what the budget deletes on disk, and what it keeps."""

from __future__ import annotations

from pathlib import Path

from acq.monitoring.monitor_windows import FolderWindows
from acq.monitoring.retention import WindowFiles


def test_the_budget_deletes_the_files_it_chose_counts_the_copies_and_deletes_nothing_when_it_cannot_fit(
        tmp_path: Path) -> None:
    windows = FolderWindows(tmp_path, keep=10)
    for i, copied in ((0, False), (1, False), (6, True), (7, True), (8, True)):
        path = tmp_path / f"w{i}{'c' if copied else ''}.h5"
        path.write_bytes(b"x" * 1000)
        path.with_suffix(".result.json").write_bytes(b"y" * 100)  # a sibling <stem>.* goes with its window
        # window 0 this monitor's baseline, the copy of window 6 the other monitor's
        windows.add(WindowFiles(i, path, done=True, protected=i in (0, 6), key=path.stem, copied=copied))
    assert windows.disk_bytes() == 5500
    assert windows.kept_copies() == 1
    assert windows.make_room(3000, budget_bytes=4000) == (False, 0)  # 0 and the copy of 6 leave 2200 B: no room
    assert sorted(p.name for p in tmp_path.glob("*.h5")) == ["w0.h5", "w1.h5", "w6c.h5", "w7c.h5", "w8c.h5"]
    assert windows.make_room(2000, budget_bytes=5300) == (True, 2)  # the other monitor's 7 and 8 go first
    assert sorted(p.name for p in tmp_path.iterdir()) == ["w0.h5", "w0.result.json", "w1.h5", "w1.result.json",
                                                         "w6c.h5", "w6c.result.json"]
    assert windows.disk_bytes() == 3300
    assert windows.path("w1") == tmp_path / "w1.h5"
