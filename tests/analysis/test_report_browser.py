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
  const title = document.querySelector("h1");
  const verdict = document.getElementById("verdict");
  const headline = verdict ? verdict.querySelector(".headline") : null;
  const page = {
    afterTitle: title.nextElementSibling ? title.nextElementSibling.id : null,
    verdict: verdict ? verdict.innerText : "",
    verdictTop: verdict ? verdict.getBoundingClientRect().top : null,
    headlineBottom: headline ? headline.getBoundingClientRect().bottom : null,
    sectionTops: [...document.querySelectorAll("section")]
      .filter((section) => section !== verdict)
      .map((section) => section.getBoundingClientRect().top),
    scrollWidth: document.documentElement.scrollWidth,
    innerWidth: window.innerWidth,
    innerHeight: window.innerHeight,
  };
  const check = document.createElement("pre");
  check.id = "check";
  check.textContent = JSON.stringify({ tables, images, page });
  document.body.append(check);
  if (window.parent !== window) window.parent.postMessage(check.textContent, "*");
});
</script>
"""
"""Appended to a copy of the page: on load, writes what the browser rendered as JSON (and
hands it to the page that frames it, if any)."""

PHONE = (390, 844)
"""A phone's viewport in CSS pixels (width, height)."""

FRAME = """<!DOCTYPE html><html><body style="margin: 0">
<iframe src="index.html" width="{width}" height="{height}" style="border: 0"></iframe>
<script>
window.addEventListener("message", (event) => {{
  const check = document.createElement("pre");
  check.id = "check";
  check.textContent = event.data;
  document.body.append(check);
}});
</script></body></html>
"""
"""A page that shows the report in a frame of a phone's viewport: headless Chromium's window is
never narrower than 500 pixels, a frame's viewport is as narrow as the frame."""


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


def render(chromium: str, report: Path, folder: Path, phone: bool = False) -> dict[str, Any]:
    """What headless Chromium rendered of the report, in a desktop window or, with ``phone``,
    in a frame of a phone's size."""
    text = (report / "index.html").read_text()
    (folder / "index.html").write_text(text.replace("</body>", CHECK + "</body>"))
    page = folder / "index.html"
    if phone:
        page = folder / "phone.html"
        page.write_text(FRAME.format(width=PHONE[0], height=PHONE[1]))
    try:
        result = subprocess.run(
            [
                chromium,
                "--headless",
                "--no-sandbox",
                "--disable-gpu",
                "--disable-dev-shm-usage",
                "--hide-scrollbars",
                "--window-size=1280,900",
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


@pytest.fixture(scope="module")
def rendered(
    chromium: str, report: Path, tmp_path_factory: pytest.TempPathFactory
) -> dict[str, Any]:
    """What headless Chromium rendered of the report in a desktop window."""
    return render(chromium, report, tmp_path_factory.mktemp("browser"))


@pytest.fixture(scope="module")
def on_a_phone(
    chromium: str, report: Path, tmp_path_factory: pytest.TempPathFactory
) -> dict[str, Any]:
    """What headless Chromium rendered of the report in a phone-sized frame."""
    return render(chromium, report, tmp_path_factory.mktemp("phone"), phone=True)


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


def test_the_verdict_comes_first_with_the_campaigns_numbers(
    rendered: dict[str, Any], campaign: Path, report: Path
) -> None:
    """Right below the title, before any of the study's sections: the failures, the distinct
    mechanisms, the worst failure, which tester found what and the commands to keep them."""
    page = rendered["page"]
    assert page["afterTitle"] == "verdict"
    assert all(top > page["verdictTop"] for top in page["sectionTops"])
    runs = [json.loads(path.read_text()) for path in campaign.glob("runs/*/summary.json")]
    failures, episodes = sum(r["failures"] for r in runs), sum(r["episodes"] for r in runs)
    text = " ".join(page["verdict"].split())
    assert f"{failures} unsafe failures in {episodes} episodes of {len(runs)} runs" in text
    verdict = json.loads((report / "summary.json").read_text())["verdict"]
    assert f"{len(verdict['classes'])} distinct mechanisms" in text
    assert all(name in text for name in verdict["classes"])
    assert f"{verdict['clusters']} clusters" in text
    assert "The worst failure" in text
    assert "Which tester found what" in text
    assert rendered["tables"]["table-verdict_testers"]["shown"]
    assert "hazardhunt export" in text
    assert "hazardhunt regress" in text


def test_on_a_phone_nothing_is_wider_than_the_screen(on_a_phone: dict[str, Any]) -> None:
    """At a phone's width the page does not scroll sideways (wide tables scroll in their own
    box, pictures shrink) and its first screen shows the verdict's numbers."""
    page = on_a_phone["page"]
    assert (page["innerWidth"], page["innerHeight"]) == PHONE
    assert page["scrollWidth"] <= page["innerWidth"]
    assert page["afterTitle"] == "verdict"
    assert 0 <= page["verdictTop"] < page["headlineBottom"] <= page["innerHeight"]
    assert all(top > page["headlineBottom"] for top in page["sectionTops"])
    assert all(image["width"] > 0 and image["shown"] for image in on_a_phone["images"])
