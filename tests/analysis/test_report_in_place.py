"""Two reports of one directory that finish at once both succeed, and a whole report stays."""

import threading
from pathlib import Path

from hazardhunt.analysis import report as report_module


def test_reports_finishing_at_once_take_turns_and_leave_one_whole_report(tmp_path: Path) -> None:
    final = tmp_path / "report"
    errors: list[BaseException] = []

    def write_reports(writer: int) -> None:
        for attempt in range(100):
            written = tmp_path / f".report-{writer}{attempt}.partial"
            written.mkdir()
            (written / "index.html").write_text(f"{writer} {attempt}")
            try:
                report_module._put_in_place(written, final)
            except OSError as error:  # the race this test looks for
                errors.append(error)

    threads = [threading.Thread(target=write_reports, args=(writer,)) for writer in (1, 2)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    assert errors == []
    assert (final / "index.html").read_text().endswith(" 99")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["report"]
