"""The report as a person sees it: ``index.html`` opened in headless Chromium.

Chromium is Debian's ``chromium`` package; ``make browser`` (and so ``make test``) installs
it. Without it the tests are skipped, except under CI, where they must run.
"""

import html
import json
import os
import re
import shutil
import subprocess
from pathlib import Path
from typing import Any

import pytest

# Slow: the same campaign's report in a real browser; CI runs it with `make test-slow`.
pytestmark = pytest.mark.slow

TABLES = [
    "failures_per_run",
    "classes",
    "class_discovery",
    "clusters",
    "clusters_vs_classes",
    "lesson_1",
    "runtime",
    "reward_hacking",
    "failure_rates",
    "runs",
]
"""Tables the campaign's report must show, by the name in ``id="table-NAME"``."""

MIN_IMAGES = 7
"""The bar chart, classes against episodes, clusters, loitering, learning curves, heat map,
rates, and a picture per class."""

CHECK = """
<script>
window.addEventListener("load", () => {
  const shown = (element) => element.getBoundingClientRect().width > 0;
  const tables = {};
  for (const figure of document.querySelectorAll("figure.table")) {
    const table = figure.querySelector("table");
    const link = figure.querySelector("figcaption a");
    tables[figure.id] = {
      columns: table ? table.querySelectorAll("thead th").length : 0,
      rows: table ? table.querySelectorAll("tbody tr").length : 0,
      shown: shown(figure),
      csv: link ? link.getAttribute("href") : null,
    };
  }
  const images = [...document.images].map((image) => ({
    alt: image.alt,
    complete: image.complete,
    width: image.naturalWidth,
    height: image.naturalHeight,
    shown: shown(image),
  }));
  const check = document.createElement("pre");
  check.id = "check";
  check.textContent = JSON.stringify({ tables, images });
  document.body.append(check);
});
</script>
"""
"""Appended to a copy of the page: on load, writes what the browser rendered as JSON."""


@pytest.fixture(scope="session")
def chromium() -> str:
    """The ``chromium`` command; skips (fails under CI) when it is not installed."""
    command = shutil.which("chromium")
    if command is None:
        message = "chromium is not installed; `make browser` installs it"
        if os.environ.get("CI"):
            pytest.fail(message)
        pytest.skip(message)
    return command


@pytest.fixture(scope="module")
def rendered(
    chromium: str, report: Path, tmp_path_factory: pytest.TempPathFactory
) -> dict[str, Any]:
    """What headless Chromium rendered of the report: its tables and images."""
    folder = tmp_path_factory.mktemp("browser")
    page = folder / "index.html"
    text = (report / "index.html").read_text()
    page.write_text(text.replace("</body>", CHECK + "</body>"))
    try:
        result = subprocess.run(
            [
                chromium,
                "--headless",
                "--no-sandbox",
                "--disable-gpu",
                "--disable-dev-shm-usage",
                f"--user-data-dir={folder / 'profile'}",
                "--virtual-time-budget=10000",
                "--dump-dom",
                page.as_uri(),
            ],
            capture_output=True,
            text=True,
            timeout=120,
            check=False,
        )
    except subprocess.TimeoutExpired:
        pytest.fail("chromium did not render the report within 120 s")
    found = re.search(r'<pre id="check">(.*?)</pre>', result.stdout, re.DOTALL)
    assert found, f"the page's check did not run (exit {result.returncode}):\n{result.stderr}"
    return dict(json.loads(html.unescape(found.group(1))))


def test_report_makes_no_network_requests(report: Path) -> None:
    """The page is self-contained: no address to fetch, so it works offline."""
    text = (report / "index.html").read_text()
    remote = re.findall(r"""(?:src|href)\s*=\s*["']?(?:https?:)?//[^"'\s>]*""", text)
    assert remote == []
    assert "url(http" not in text
    sources = re.findall(r'<img\b[^>]*?\ssrc="([^"]*)"', text)
    assert sources
    assert [s for s in sources if not s.startswith("data:image/")] == []


@pytest.mark.parametrize("name", TABLES)
def test_table_is_shown_with_data(rendered: dict[str, Any], name: str, report: Path) -> None:
    """Each of the study's tables is on the page, with rows and a working CSV link."""
    table = rendered["tables"].get(f"table-{name}")
    assert table is not None, f"no table-{name} in {sorted(rendered['tables'])}"
    assert table["columns"] >= 2
    assert table["rows"] >= 1
    assert table["shown"]
    assert table["csv"] == f"tables/{name}.csv"
    assert (report / table["csv"]).is_file()


def test_every_image_loads(rendered: dict[str, Any]) -> None:
    """Every figure and animation is decoded by the browser and takes up room on the page."""
    images = rendered["images"]
    assert len(images) >= MIN_IMAGES
    broken = [
        image["alt"]
        for image in images
        if not (image["complete"] and image["width"] > 0 and image["height"] > 0)
    ]
    assert broken == []
    assert all(image["shown"] for image in images)
    assert all(image["alt"] for image in images), "every image has alternative text"
