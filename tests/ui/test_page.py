"""The web page in a real Chromium, as a person uses it (Playwright, Debian's chromium).

Enroll three of the bundled examples through the page, wait until they are ready,
search with another pose of one of them: the first card is the right kind of object, and the 3D
views draw the meshes (non-blank pixels). With ``SHAPES_UI_SCREENSHOTS=docs/ui`` the
screenshots of the search (with the side-by-side view) and the gallery are saved there.
"""

from __future__ import annotations

import gzip
import os
import re
import shutil
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
import trimesh
from conftest import example, floor_points_ply, noisy_depth_scan, with_a_far_half_copy

from app.search.service import smoothed_sentence
from benchmarks.common import EXAMPLES, Service
from tests.service.conftest import migrated_service, running
from worker.engine.mesh_io import load_mesh
from worker.engine.scans import read_pcd
from worker.evaluation.partial import noisy_surface
from worker.evaluation.samples import DEPTH_SAMPLE, FLOOR_SAMPLE, PARTIAL_SAMPLE

pytestmark = [pytest.mark.slow, pytest.mark.service]

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
# Headless WebGL without a GPU (SwiftShader), and no network calls of Chromium's own.
ARGS = [
    "--no-sandbox",
    "--use-angle=swiftshader",
    "--enable-unsafe-swiftshader",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
]
ENROLL = {"quadruped-0": "quadruped", "biped-0": "biped", "hand-0": "hand"}
SCREENSHOTS = os.environ.get("SHAPES_UI_SCREENSHOTS")
# Pixels of a 3D view that differ from its clear colour (#eef1f5) by more than a little.
DRAWN_PIXELS = """(id) => {
  const source = document.getElementById(id);
  const copy = document.createElement("canvas");
  copy.width = source.width;
  copy.height = source.height;
  const g = copy.getContext("2d");
  g.drawImage(source, 0, 0);
  const data = g.getImageData(0, 0, copy.width, copy.height).data;
  let drawn = 0;
  for (let i = 0; i < data.length; i += 4) {
    const off = Math.abs(data[i] - 0xee) + Math.abs(data[i + 1] - 0xf1)
      + Math.abs(data[i + 2] - 0xf5);
    if (off > 30) drawn++;
  }
  return drawn;
}"""


@pytest.fixture(scope="module")
def site(tmp_path_factory) -> Iterator[Service]:
    with running(migrated_service(tmp_path_factory, "ui")) as svc:
        yield svc


@pytest.fixture(scope="module")
def page(site):
    if CHROMIUM is None:
        pytest.skip("Chromium is not installed (./scripts/test.sh installs Debian's chromium)")
    from playwright.sync_api import sync_playwright

    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=ARGS, headless=True)
        page = browser.new_page(viewport={"width": 1280, "height": 900})
        errors: list[str] = []
        page.on("pageerror", lambda e: errors.append(str(e)))
        # Nothing the page asks for is missing (the favicon included).
        page.on(
            "response",
            lambda r: r.status == 404 and errors.append(f"404 {r.url}"),
        )
        page.goto(site.url + "/")
        yield page
        browser.close()
        assert errors == [], errors


def shoot(page, name: str) -> None:
    if SCREENSHOTS:
        Path(SCREENSHOTS).mkdir(parents=True, exist_ok=True)
        page.screenshot(path=str(Path(SCREENSHOTS) / f"{name}.png"), full_page=True)


class FirstRequestHeld:
    """Within it, the first request whose URL matches ``url`` is held back (the others
    pass) until :meth:`release`; the route is gone on leaving, whatever happened."""

    def __init__(self, page, url: re.Pattern[str]) -> None:
        self.page, self.url, self.held = page, url, []

    def __enter__(self) -> FirstRequestHeld:
        self.page.route(self.url, lambda r: r.continue_() if self.held else self.held.append(r))
        return self

    def __exit__(self, *exc: object) -> None:
        self.page.unroute(self.url)

    def made(self) -> str:
        """Wait until the page has made the request held; its URL."""
        while not self.held:
            self.page.wait_for_timeout(20)
        return str(self.held[0].request.url)

    def release(self) -> None:
        """Let it through and wait until the page has read its answer."""
        request = self.held[0].request
        with self.page.expect_response(lambda r: r.request == request, timeout=180_000):
            self.held[0].continue_()
        self.page.evaluate("() => new Promise((done) => setTimeout(done, 200))")


def search_for(page, path: Path) -> None:
    """Search the page with the file at ``path`` and wait for its answer's progress line."""
    page.click("#tab-search")
    page.set_input_files("#file-search", str(path))
    page.wait_for_function(
        "(name) => document.getElementById('search-progress').textContent.startsWith(name + ': ')",
        arg=Path(path).name,
        timeout=180_000,
    )


def test_enroll_three_meshes_through_the_page(page, site):
    # Nothing searched or opened yet: no empty 3D panels, no detail with live buttons.
    assert page.locator("#compare").is_hidden() and page.locator("#detail").is_hidden()
    page.click("#tab-enroll")
    for name, label in ENROLL.items():
        page.set_input_files("#enroll-files", str(example(name)))
        page.fill("#enroll-label", label)
        page.click("#enroll-form button[type=submit]")
    rows = page.locator("#enroll-table tbody tr")
    rows.nth(len(ENROLL) - 1).wait_for()
    for i in range(len(ENROLL)):
        status = rows.nth(i).locator("td").nth(2)
        page.wait_for_function(
            "(cell) => ['ready', 'failed'].includes(cell.textContent) || "
            "cell.textContent.startsWith('failed')",
            arg=status.element_handle(),
            timeout=180_000,
        )
        assert status.inner_text() == "ready"
    listed = site.client.get("/meshes", params={"status": "ready"}).json()
    assert {(m["name"], m["label"]) for m in listed["items"]} == set(ENROLL.items())
    shoot(page, "enroll")


def test_search_with_another_pose_shows_the_right_object_in_3d(page):
    page.click("#tab-search")
    page.set_input_files("#file-search", str(example("quadruped-1")))
    cards = page.locator("#search-results .card")
    cards.first.wait_for(timeout=180_000)
    assert cards.count() == len(ENROLL)
    assert cards.first.locator(".label").inner_text() == "quadruped"
    # The thumbnail loads after its card is drawn: on a busy machine, some time after.
    page.wait_for_function(
        "() => { const img = document.querySelector('#search-results .card img');"
        " return img && img.complete && img.naturalWidth === 256; }",
        timeout=60_000,
    )
    # The best match opens beside the query at once, both in one view.
    page.locator("#compare").wait_for(state="visible")
    page.wait_for_function(
        "() => document.getElementById('view-compare').dataset.models === '2'", timeout=60_000
    )
    page.wait_for_function(f"() => ({DRAWN_PIXELS})('view-compare') > 4000", timeout=60_000)
    assert page.locator("#caption-match").inner_text().startswith("Match 1: quadruped-0")
    assert "3 shapes" in page.locator("#service-status").inner_text()
    cards.nth(1).click()  # another card replaces the match
    page.wait_for_function(
        "() => document.getElementById('caption-match').textContent.startsWith('Match 2')"
    )


def test_a_search_answering_late_leaves_the_newer_search_shown(page):
    """The first file's answer is held back until the second file's is shown; when it
    comes, the page keeps showing the second's."""
    cards = (
        "() => [...document.querySelectorAll('#search-results .card')].map((c) => c.dataset.meshId)"
    )
    with FirstRequestHeld(page, re.compile(r"/query$")) as first:
        page.click("#tab-search")
        page.set_input_files("#file-search", [])  # the page's input may hold this file
        page.set_input_files("#file-search", str(example("quadruped-1")))
        first.made()
        search_for(page, example("biped-2"))
        shown = page.evaluate(cards)
        first.release()
    assert page.locator("#search-progress").inner_text().startswith("biped-2")
    assert page.evaluate(cards) == shown and shown


def test_the_gallery_lists_and_opens_a_mesh_in_3d(page):
    page.click("#tab-gallery")
    cards = page.locator("#gallery-grid .card")
    cards.first.wait_for()
    assert cards.count() == len(ENROLL)
    cards.nth(1).press("Enter")  # keyboard reachable
    page.locator("#detail").wait_for(state="visible")
    top = page.locator("#detail").evaluate("(e) => e.getBoundingClientRect().top")
    assert 0 <= top < page.viewport_size["height"] / 2  # scrolled to, not below the grid
    page.wait_for_function(f"() => ({DRAWN_PIXELS})('view-detail') > 2000", timeout=60_000)
    facts = page.locator("#detail-meta").inner_text()
    assert "ready" in facts and "100% described" in facts
    assert "in the file; the descriptor resampled it to" in facts
    shoot(page, "gallery")


def test_a_search_says_when_part_of_the_file_was_left_out(page, tmp_path):
    _, both = with_a_far_half_copy(example("quadruped-2"))
    path = tmp_path / "quadruped-2-and-a-copy.off"
    path.write_bytes(both)
    search_for(page, path)
    progress = page.locator("#search-progress").inner_text()
    assert "Only 80% of the query file's surface was described" in progress, progress
    assert page.locator("#search-results .card .label").first.inner_text() == "quadruped"


def test_a_partial_scan_is_ranked_by_its_parts_and_the_page_says_so(page):
    """The walk-through's partial example: the page says how much seems missing, and
    every card has the parts bar."""
    search_for(page, EXAMPLES / PARTIAL_SAMPLE)
    progress = page.locator("#search-progress").inner_text()
    assert "matches are ranked by the parts that are there" in progress, progress
    cards = page.locator("#search-results .card")
    assert cards.first.locator(".label").inner_text() == "quadruped"
    assert "PARTS" in cards.first.locator(".bars").inner_text()
    # No confidence, and the card says why rather than leaving it out.
    assert "no confidence (ranked by its parts)" in cards.first.inner_text()
    shoot(page, "partial")


def test_a_depth_camera_s_scan_is_searched_and_drawn_beside_its_match(page):
    """The example organized cloud (.pcd): triangulated by its grid, ranked by its parts
    and fitted rigidly to the best, each card saying how much of the view it holds, the
    answer that the fittest holds it less than its own object's surface would (the
    gallery has the quadruped in another pose only), and drawn in 3D beside the quadruped
    it finds."""
    search_for(page, EXAMPLES / DEPTH_SAMPLE)
    first = page.locator("#search-results .card").first
    assert first.locator(".label").inner_text() == "quadruped"
    assert re.search(r"holds \d+% of the view", first.inner_text()), first.inner_text()
    progress = page.locator("#search-progress").inner_text()
    assert f"The query is {depth_cloud_phrase()}." in progress, progress
    assert "One view of its object" in progress and "fitted to it rigidly" in progress
    assert "under the 90% its own object's surface holds" in progress, progress  # not found
    page.wait_for_function(
        "() => document.getElementById('view-compare').dataset.models === '2'", timeout=60_000
    )
    page.wait_for_function(f"() => ({DRAWN_PIXELS})('view-compare') > 4000", timeout=60_000)
    shoot(page, "depth")


def test_a_noisy_depth_scan_is_said_to_be_smoothed(page, tmp_path):
    """The example depth scan with a depth camera's noise (0.4% of its diagonal): the
    answer's note on the page says it looked noisy and was smoothed before its fit."""
    noisy = tmp_path / "noisy-depth.pcd"
    noisy.write_bytes(noisy_depth_scan(0.004))
    search_for(page, noisy)
    progress = page.locator("#search-progress").inner_text()
    assert "One view of its object" in progress and "fitted to it rigidly" in progress
    assert "Its surface looked noisy" in progress and "was smoothed before it was fitted" in (
        progress
    )
    first = page.locator("#search-results .card").first
    assert first.locator(".label").inner_text() == "quadruped"


def test_a_noisy_whole_is_said_to_be_smoothed(page, tmp_path):
    """Another pose of the quadruped with noise of 1% of its diagonal: the page says it
    looked noisy and was smoothed before it was described, and finds the quadruped."""
    mesh = load_mesh(EXAMPLES / "quadruped-2.off.gz")
    noisy = noisy_surface(mesh, 1.0, np.random.default_rng(0))
    path = tmp_path / "noisy-quadruped.off"
    trimesh.Trimesh(noisy.vertices, noisy.faces, process=False).export(path)
    search_for(page, path)
    progress = page.locator("#search-progress").inner_text()
    assert progress.endswith(smoothed_sentence("described")), progress
    assert page.locator("#search-results .card .label").first.inner_text() == "quadruped"


def test_a_partial_answer_says_what_ranked_it_and_what_was_measured(site):
    """The answer names the modalities that ranked it (not the whole ones it did not use),
    and the missing share as what it is: an estimate on the parts' scale grid, rounded,
    with its bounds."""
    data = (EXAMPLES / PARTIAL_SAMPLE).read_bytes()
    body = site.client.post(
        "/query", files={"file": (Path(PARTIAL_SAMPLE).name, data)}, data={"k": "3"}
    ).json()
    assert "parts" in body["modalities"]
    assert body["modalities"] == [m for m, w in body["weights"].items() if w > 0]
    assert set(body["modalities"]) <= set(body["matches"][0]["scores"])
    partial = body["partial"]
    low, high = partial["missing_share_range"]
    assert low <= partial["missing_share"] <= high
    assert partial["missing_share"] == round(partial["missing_share"], 2)
    assert f"Between {round(100 * low)}% and {round(100 * high)}%" in partial["note"]


def test_an_error_shows_the_services_sentence(page, tmp_path):
    bad = tmp_path / "broken.off"
    bad.write_text("OFF\n3 1 0\n0 0 0\n")
    page.click("#tab-search")
    page.set_input_files("#file-search", str(bad))
    alert = page.locator("#alert")
    alert.wait_for(state="visible", timeout=120_000)
    assert "Traceback" not in alert.inner_text() and len(alert.inner_text()) > 20
    # Nothing of the previous search stays beside the error.
    assert page.locator("#compare").is_hidden()
    assert page.locator("#search-results .card").count() == 0


def test_calibration_says_what_it_needs_then_draws_the_roc(page, site):
    page.click("#tab-calibration")
    summary = page.locator("#calibration-summary")
    page.wait_for_function(
        "() => document.getElementById('calibration-summary').textContent.length > 0"
    )
    assert "enroll more meshes with labels" in summary.inner_text()  # the service's sentence
    # Four birds and three more quadrupeds (with the one enrolled): 12 genuine and 10
    # impostor pairs at least, enough.
    named = [(f"bird-{i}", "bird") for i in range(4)]
    named += [(f"quadruped-{i}", "quadruped") for i in range(1, 4)]
    ids = [site.upload(name, label).json()["id"] for name, label in named]
    for mesh_id in ids:
        assert site.wait_mesh(mesh_id)["status"] == "ready"
    page.click("#tab-search")
    page.click("#tab-calibration")
    page.locator("#calibration-histogram").wait_for(state="visible", timeout=60_000)
    assert "Equal error rate" in summary.inner_text()
    eer = site.client.get("/calibration").json()["eer"]
    assert page.locator("#calibration-roc").is_visible() == (eer > 0)
    # Next to the ROC, the fusion's weights and why (two labels of three or more: the
    # preset's, and the sentence says what learning needs).
    fusion = page.locator("#calibration-fusion").inner_text()
    assert fusion.startswith("Fusion weights: GDM 0, DDT 0.5, SPECTRUM 1 (the preset's).")
    assert "learning needs at least 3 labels" in fusion
    assert page.locator("#calibration-table tbody tr").count() >= 3
    assert page.locator("#calibration-folds").is_hidden()  # nothing was cross-validated
    # A third label of three: the gallery learns its fusion, and the page shows the folds.
    hands = [site.upload(f"hand-{i}", "hand").json()["id"] for i in range(3)]
    for mesh_id in hands:
        assert site.wait_mesh(mesh_id)["status"] == "ready"
    folds = page.locator("#calibration-folds")
    deadline = time.monotonic() + 60
    while not folds.is_visible():
        assert time.monotonic() < deadline, page.locator("#calibration-fusion").inner_text()
        page.click("#tab-search")
        page.click("#tab-calibration")
        page.wait_for_timeout(500)
    # A sentence a person reads, the cross-validation's figures folded under it.
    fusion = page.locator("#calibration-fusion").inner_text()
    assert "cross-validation" in fusion and ("learned" in fusion or "the preset's" in fusion)
    assert " t " not in fusion and "points of loss" not in fusion
    numbers = page.locator("#calibration-fusion-numbers")
    assert not numbers.locator("p").is_visible()  # folded until asked for
    numbers.locator("summary").click()
    assert "corrected resampled t" in numbers.locator("p").inner_text()
    summary = folds.locator("summary")
    assert summary.inner_text().startswith("How the fusion was chosen: ")
    assert " folds in 10 rounds, a gain of " in summary.inner_text()
    rows = folds.locator("tbody tr")
    assert not rows.first.is_visible()  # folded until asked for
    summary.click()
    assert rows.first.is_visible()
    assert rows.count() >= 3 * 10 + 1 and rows.last.locator("td").first.inner_text() == "mean"
    assert rows.last.locator("td").nth(2).inner_text() == "11"  # 4 birds, 4 quadrupeds, 3 hands
    assert [rows.nth(i).locator("td").first.inner_text() for i in (0, rows.count() - 2)] == [
        "1",
        "10",
    ]  # round of the first and the last fold


def test_the_comparison_stays_in_view_in_one_frame_and_one_orientation(page, site):
    """At 1280 x 900 with the default 8 matches, the query and the best match are drawn
    in one 3D view above the cards, in view without scrolling, the match turned (a half
    turn, never a mirror image) to face as the query does."""
    assert site.client.get("/meshes").json()["total"] >= 8
    _wait_for_the_reference(site)
    page.click("#tab-search")
    page.set_input_files("#file-search", str(example("quadruped-3")))
    cards = page.locator("#search-results .card")
    page.wait_for_function(
        "() => document.querySelectorAll('#search-results .card').length === 8", timeout=180_000
    )
    canvas = page.locator("#view-compare")
    page.wait_for_function(
        "() => document.getElementById('view-compare').dataset.models === '2'", timeout=60_000
    )
    box = canvas.bounding_box()
    assert page.evaluate("() => window.scrollY") == 0
    assert 0 <= box["y"] and box["y"] + box["height"] <= 900, box
    assert box["y"] < cards.first.bounding_box()["y"]  # above the cards
    turns = ["1,1,1", "-1,-1,1", "-1,1,-1", "1,-1,-1"]
    assert canvas.get_attribute("data-turn") in turns
    # The turn chosen undoes a shape's half turn, whichever it is (align.js on a figure
    # with no symmetry).
    undone = page.evaluate(
        """async () => {
        const { bestTurn, TURNS } = await import('/static/align.js');
        const figure = [];
        for (let i = 0; i < 300; i++) {
          const t = i / 300;
          figure.push([Math.cos(7 * t) + t, 0.5 * Math.sin(5 * t) + t * t, t * t * t - 0.3]);
        }
        return TURNS.map(([a, b, c]) =>
          bestTurn(figure, figure.map(([x, y, z]) => [a * x, b * y, c * z])).turn.join(','));
      }"""
    )
    assert undone == turns
    page.wait_for_function(f"() => ({DRAWN_PIXELS})('view-compare') > 4000", timeout=60_000)
    shoot(page, "search")


def _wait_for_the_reference(site) -> None:
    """Until the collector has fitted the gallery's yardstick of closeness (each round
    after changes)."""
    deadline = time.monotonic() + 60
    while not site.query("quadruped-3", k=1).json()["matches"][0]["closeness"]:
        assert time.monotonic() < deadline, "no closeness in the answers"
        time.sleep(0.5)


def test_score_bars_mean_the_same_everywhere_and_only_modalities_that_count(page, site):
    """Each bar is the match's closeness on the collection's scale (the share of its pairs
    of different objects farther apart), as the answer gives it, for each modality with a
    weight: the GDM, weighed 0 by the default fusion, has none. The page's own answer is
    read (the collector may refit the yardstick between two searches)."""
    page.click("#tab-search")
    # Cleared first: choosing the file the last search chose fires no change event.
    page.set_input_files("#file-search", [])
    with page.expect_response(
        lambda r: r.url.endswith("/query") and r.request.method == "POST", timeout=180_000
    ) as answer:
        page.set_input_files("#file-search", str(example("quadruped-3")))
    body = answer.value.json()
    assert body["weights"]["gdm"] == 0 and "gdm" not in body["modalities"]
    page.wait_for_function(
        "(n) => document.querySelectorAll('#search-results .card').length === n",
        arg=len(body["matches"]),
    )
    cards = page.locator("#search-results .card")
    for i, match in enumerate(body["matches"]):
        bars = cards.nth(i).locator(".bar")
        shown = [bars.nth(j).get_attribute("data-modality") for j in range(bars.count())]
        assert shown == body["modalities"]
        for j, modality in enumerate(shown):
            closeness = float(bars.nth(j).get_attribute("data-closeness"))
            assert closeness == pytest.approx(match["closeness"][modality])
            width = bars.nth(j).locator("span").evaluate("(e) => e.style.width")
            # CSS serializes a percentage to six significant digits.
            shown_width = float(width.removesuffix("%"))
            assert shown_width == pytest.approx(max(2, 100 * closeness), rel=1e-5)
    # The best match, another pose of the same figure, is closer than most pairs of
    # different objects in every modality that ranked it.
    assert min(body["matches"][0]["closeness"][m] for m in body["modalities"]) > 0.5


def test_the_gallery_sorts_and_says_which_meshes_failed(page, site):
    broken = b"OFF\n4 2 0\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 1 2\n3 0 1 9\n"
    failed = site.client.post("/meshes", files={"file": ("broken-one.off", broken)}).json()
    assert site.wait_mesh(failed["id"])["status"] == "failed"
    # The tab's own listing (newest first) is held back until the listing by name has
    # been drawn: a late, older answer must not replace the newer one.
    sorted_by_name = """() => {
      const titles = [...document.querySelectorAll('#gallery-grid .card .title')]
        .map((t) => t.textContent);
      return titles.length > 1 && titles.every((t, i) => i === 0 || titles[i - 1] <= t);
    }"""
    with FirstRequestHeld(page, re.compile(r"/meshes\?")) as first:
        page.evaluate(  # the page is shared: no filter left by another test, newest first
            """() => { for (const [id, value] of [['gallery-label', ''], ['gallery-status', ''],
                ['gallery-sort', 'newest']]) document.getElementById(id).value = value; }"""
        )
        page.click("#tab-gallery")
        first.made()
        page.select_option("#gallery-sort", "name")
        page.wait_for_function(sorted_by_name)  # the service sorts; this checks it did
        assert "sort=newest" in first.made()
        first.release()
    assert page.evaluate(sorted_by_name)
    card = page.locator(f'#gallery-grid .card[data-mesh-id="{failed["id"]}"]')
    assert "failed: " in card.inner_text() and "not described yet" not in card.inner_text()
    page.select_option("#gallery-sort", "newest")
    page.wait_for_function(
        "(id) => document.querySelector('#gallery-grid .card').dataset.meshId === String(id)",
        arg=failed["id"],
    )


def test_a_perfectly_separated_calibration_shows_the_gap_not_an_empty_box(page, site):
    """Birds against hands: every pair of the same label scores below every pair of
    different labels, so the ROC lies on its axes; the page says so and draws how far
    apart the two kinds of pairs' scores lie."""
    assert site.client.post("/collections", json={"name": "apart"}).status_code == 201
    ids = [
        site.upload(f"{kind}-{i}", kind, collection="apart").json()["id"]
        for kind in ("bird", "hand")
        for i in range(4)
    ]
    for mesh_id in ids:
        assert site.wait_mesh(mesh_id, collection="apart")["status"] == "ready"
    assert site.client.get("/collections/apart/calibration").json()["eer"] == 0
    page.reload()
    page.locator('#collection option[value="apart"]').wait_for(state="attached")
    page.select_option("#collection", "apart")
    page.click("#tab-calibration")
    page.locator("#calibration-histogram").wait_for(state="visible", timeout=60_000)
    assert page.locator("#calibration-roc").is_hidden()
    separation = page.locator("#calibration-separation").inner_text()
    assert separation.startswith("No error at any threshold")
    bars = page.locator("#calibration-histogram rect").count()
    assert bars > 2  # the frame and the bins of both kinds of pairs
    shoot(page, "calibration")
    page.select_option("#collection", "default")


def test_deleting_the_match_shown_leaves_no_stale_view(page, site):
    page.click("#tab-search")
    page.set_input_files("#file-search", str(example("biped-2")))
    best = page.locator("#search-results .card").first
    best.wait_for(timeout=180_000)
    page.locator("#compare").wait_for(state="visible")
    assert best.locator(".label").inner_text() == "biped"  # the only biped enrolled
    mesh_id = best.get_attribute("data-mesh-id")
    indexed = site.index_size()  # every collection's, as the header counts them
    page.click("#tab-gallery")
    page.fill("#gallery-label", "biped")
    page.click("#gallery-filter button[type=submit]")
    name = best.locator(".title").inner_text().split(". ", 1)[1]
    # The filtered grid's card (not one of the grid before the filter answered), and its
    # detail (not the one an earlier test left open).
    page.locator("#gallery-grid .card .title", has_text=name).click()
    page.wait_for_function(
        f"() => document.getElementById('detail-name').textContent.startsWith('#{mesh_id} ')"
    )
    page.once("dialog", lambda dialog: dialog.accept())
    page.click("#detail-delete")
    page.locator("#detail").wait_for(state="hidden")
    assert site.client.get(f"/meshes/{mesh_id}").status_code == 404
    shapes = f"{indexed - 1} shapes"
    page.wait_for_function(
        f"() => document.getElementById('service-status').textContent.includes('{shapes}')"
    )
    page.click("#tab-search")
    assert page.locator(f'#search-results .card[data-mesh-id="{mesh_id}"]').count() == 0
    assert page.locator("#compare").is_hidden()  # the deleted mesh was the match shown


def test_the_collection_picker_switches_gallery_and_search(page, site):
    assert site.client.post("/collections", json={"name": "museum"}).status_code == 201
    mesh_id = site.upload("spider-0", "spider", collection="museum").json()["id"]
    assert site.wait_mesh(mesh_id, collection="museum")["status"] == "ready"
    page.reload()
    page.locator('#collection option[value="museum"]').wait_for(state="attached")
    page.select_option("#collection", "museum")
    page.click("#tab-gallery")
    cards = page.locator("#gallery-grid .card")
    page.wait_for_function("() => document.querySelectorAll('#gallery-grid .card').length === 1")
    assert "spider-0" in cards.first.inner_text()
    page.click("#tab-search")
    page.set_input_files("#file-search", str(example("spider-1")))
    best = page.locator("#search-results .card").first
    best.wait_for(timeout=180_000)
    assert page.locator("#search-results .card").count() == 1
    assert best.get_attribute("data-mesh-id") == str(mesh_id)
    page.select_option("#collection", "default")  # as the page was before this test


def depth_cloud_phrase() -> str:
    """How the page names the example depth scan (its grid as the file has it)."""
    cloud = read_pcd(gzip.decompress((EXAMPLES / DEPTH_SAMPLE).read_bytes()))[2]
    assert cloud.grid is not None
    width, height = cloud.grid
    return (
        f"a scanner's point cloud: {cloud.points:,} points on a {width} x {height} grid, "
        "triangulated by it"
    )


def enrolled_facts(page, site, name: str, data: bytes) -> str:
    """Enroll ``data`` as ``name`` in the collection ``scans`` and open its card on the
    gallery: the facts its detail shows."""
    enrolled = site.client.post("/collections/scans/meshes", files={"file": (name, data)})
    assert enrolled.status_code == 202, enrolled.text
    mesh_id = enrolled.json()["id"]
    assert site.wait_mesh(mesh_id, collection="scans")["status"] == "ready"
    page.reload()
    page.locator('#collection option[value="scans"]').wait_for(state="attached")
    page.select_option("#collection", "scans")
    page.click("#tab-gallery")
    card = page.locator(f'#gallery-grid .card[data-mesh-id="{mesh_id}"]')
    card.wait_for()
    card.press("Enter")
    page.locator("#detail").wait_for(state="visible")
    facts: str = page.locator("#detail-meta").inner_text()
    return facts


def test_an_enrolled_scan_says_it_was_a_point_cloud(page, site):
    assert site.client.post("/collections", json={"name": "scans"}).status_code == 201
    data = (EXAMPLES / DEPTH_SAMPLE).read_bytes()
    enrolled = site.client.post(
        "/collections/scans/meshes", files={"file": (DEPTH_SAMPLE.name, data)}
    )
    assert enrolled.status_code == 202, enrolled.text
    assert site.wait_mesh(enrolled.json()["id"], collection="scans")["status"] == "ready"
    page.reload()
    page.locator('#collection option[value="scans"]').wait_for(state="attached")
    page.select_option("#collection", "scans")
    page.click("#tab-gallery")
    page.wait_for_function("() => document.querySelectorAll('#gallery-grid .card').length === 1")
    page.locator("#gallery-grid .card").first.press("Enter")
    page.locator("#detail").wait_for(state="visible")
    facts = page.locator("#detail-meta").inner_text()
    assert f"in the file ({depth_cloud_phrase()}); the descriptor resampled it" in facts, facts
    shoot(page, "scan-detail")
    # The same quadruped on a floor, seen from above: the card says the floor was left out.
    data = (EXAMPLES / FLOOR_SAMPLE).read_bytes()
    cloud = read_pcd(gzip.decompress(data))[2]
    facts = enrolled_facts(page, site, FLOOR_SAMPLE.name, data)
    assert (
        f"({cloud.support:,} points of a floor, table or wall it stood on or against left out)"
        in facts
    ), facts
    # Its points without the grid, as a depth camera's software exports them: the same.
    facts = enrolled_facts(page, site, "floor.ply", floor_points_ply())
    assert (
        f"a scanner's point cloud: {cloud.points:,} points, triangulated as one view "
        f"({cloud.support:,} points of a floor, table or wall it stood on or against left out)"
        in facts
    ), facts
    # A whole object's points: read as the view that sees most of them, the rest hidden.
    whole = trimesh.PointCloud(load_mesh(example("quadruped-2")).vertices)
    facts = enrolled_facts(page, site, "whole.ply", whole.export(file_type="ply"))
    shown = re.search(
        r"a scanner's point cloud: ([0-9,]+) points seen from where most of it shows, "
        r"triangulated as that view \(([0-9,]+) hidden behind them left out\)",
        facts,
    )
    assert shown is not None, facts
    seen, hidden = (int(number.replace(",", "")) for number in shown.groups())
    assert seen + hidden == len(whole.vertices) and hidden > 0
    page.select_option("#collection", "default")  # as the page was before this test
