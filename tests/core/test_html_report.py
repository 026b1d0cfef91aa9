"""HTML reports: the labels x frames classes, and batch's pages as a real browser (headless Chromium) shows them."""

from __future__ import annotations

import base64
import io
import json
import re
import shutil
import subprocess

import numpy as np
import pytest
from helpers import synthetic_takes as _synthetic
from mocap_autolabel.cli import main
from mocap_autolabel.core.labeling import Labeling
from mocap_autolabel.core.overview import ABSENT, CONFIDENT, FILLED, GAP, UNCERTAIN, VERY_UNCERTAIN, label_classes
from mocap_autolabel.core.review import queue_entries

GREEN = (0x2E, 0x9E, 0x4F)  # html_report.COLOURS[CONFIDENT]


def test_label_classes_show_confidence_gaps_and_fills():
    # two labels over 10 frames: label 0 on slot 0 frames 2-4 (sure) and 7-8 (unsure); label 1 on slot 1 frames
    # 0-9 (very unsure); an unlabeled segment on slot 2 paints nothing
    lab = Labeling(names=["A", "B"], n_frames=10, n_points=3, slot=np.array([0, 0, 1, 2]),
                   start=np.array([2, 7, 0, 0]), stop=np.array([5, 9, 10, 10]), label=np.array([0, 0, 1, -1], np.int16),
                   confidence=np.array([0.99, 0.9, 0.2, 0.1], np.float32), locked=np.zeros(4, bool), info={})
    classes = label_classes(lab, confident=0.95)
    a = [ABSENT, ABSENT, CONFIDENT, CONFIDENT, CONFIDENT, GAP, GAP, UNCERTAIN, UNCERTAIN, ABSENT]
    assert classes.tolist() == [a, [VERY_UNCERTAIN] * 10]
    filled = np.zeros((2, 10), bool)
    filled[0, 5] = filled[0, 0] = True  # a fill inside the gap shows; one outside the label's span is ignored
    assert label_classes(lab, 0.95, filled)[0].tolist() == a[:5] + [FILLED] + a[6:]


def _has_green(png: bytes) -> float:
    """Share of the picture's pixels in the confident green."""
    import matplotlib.image

    rgb = (matplotlib.image.imread(io.BytesIO(png), format="png")[..., :3] * 255).round()
    return float((np.abs(rgb - GREEN).max(axis=-1) <= 2).mean())


@pytest.mark.slow
def test_batch_pages_in_a_headless_browser(tmp_path):
    pytest.importorskip("matplotlib", reason="matplotlib is not installed (pip install matplotlib)")
    chromium = shutil.which("chromium") or shutil.which("chromium-browser")
    takes = tmp_path / "takes"
    _synthetic(takes, 2, frames=300)
    (takes / "noise.c3d").write_bytes(b"not a take" * 50)
    out = tmp_path / "out"
    # one take, then the folder with the same settings: synth0 is skipped (resume knows it by its input
    # and settings), the others are done
    assert main(["batch", str(takes / "synth0.c3d"), "-o", str(out), "--html", "--solve-hand", "--quiet"]) == 0
    assert main(["batch", str(takes), "-o", str(out), "--html", "--solve-hand", "--quiet"]) == 1  # noise fails
    rows = {r["name"]: r for r in json.loads((out / "summary.json").read_text())["takes_detail"]}
    assert rows["synth0"]["skipped"] and not rows["synth1"]["skipped"]
    report = json.loads((out / "synth0.report.json").read_text())
    assert report["outputs"]["html"] == "synth0.report.html"
    page = (out / "synth0.report.html").read_text()
    pictures = re.findall(r"id='(\w+)' alt='[^']*' src='data:image/png;base64,([^']+)'", page)
    assert [p[0] for p in pictures] == ["labels", "rms"]
    assert _has_green(base64.b64decode(pictures[0][1])) > 0.2  # the take is mostly confident
    first = queue_entries(report["summary"]["uncertain_segments"])[0]  # the review queue's first entry
    a, b = first["frame_start"], first["frame_end"]
    assert f"<td><a href='#frames={a}-{b}'>{a}&ndash;{b}</a></td>" in page
    if chromium is None:
        pytest.skip("chromium is not installed (apt-get install chromium): pages checked without a browser")

    def browse(path, *flags):
        quiet = ["--disable-background-networking", "--disable-component-update", "--disable-sync", "--no-first-run"]
        done = subprocess.run([chromium, "--headless", "--no-sandbox", "--disable-gpu", *quiet, "--hide-scrollbars",
                               f"--user-data-dir={tmp_path / 'chromium'}", *flags, path.as_uri()],
                              capture_output=True, text=True, timeout=120)
        assert done.returncode == 0, done.stderr
        return done.stdout

    dom = browse(out / "index.html", "--dump-dom")
    links = re.findall(r'<a href="([^"]+)">(\w+)</a>', dom)
    assert links == [("synth0.report.html", "synth0"), ("synth1.report.html", "synth1")]  # noise: no page
    assert "not a C3D file" in dom and dom.count("<tr>") == 4
    assert re.search(r"synth0</a></td><td>ok</td>(<td[^>]*>[^<]*</td>){5}<td[^>]*>\d+\.\d\d</td>", dom)  # RMS
    dom = browse(out / "synth1.report.html", "--dump-dom")
    assert '<a id="index" href="index.html">' in dom and '<a href="synth1.labeled.c3d">' in dom
    shot = tmp_path / "shot.png"
    browse(out / "synth1.report.html", f"--screenshot={shot}", "--window-size=1200,1400")
    assert _has_green(shot.read_bytes()) > 0.05  # the browser drew the embedded picture


def test_batch_page_shows_the_fills(tmp_path):
    """batch --fill --html: the gaps the fill closed are drawn in the fill colour on the take's page."""
    pytest.importorskip("matplotlib", reason="matplotlib is not installed (pip install matplotlib)")
    import matplotlib.image
    from mocap_autolabel.html_report import COLOURS

    takes = tmp_path / "takes"
    _synthetic(takes, 1, frames=600)
    out = tmp_path / "out"
    assert main(["batch", str(takes), "-o", str(out), "--html", "--fill", "--fill-method", "spline", "--quiet"]) == 0
    report = json.loads((out / "synth0.report.json").read_text())
    assert report["fill"]["filled"] > 0
    page = (out / "synth0.report.html").read_text()
    png = re.search(r"id='labels' alt='[^']*' src='data:image/png;base64,([^']+)'", page).group(1)
    rgb = (matplotlib.image.imread(io.BytesIO(base64.b64decode(png)), format="png")[..., :3] * 255).round()
    orange = np.array([int(COLOURS[FILLED][i:i + 2], 16) for i in (1, 3, 5)])
    assert (np.abs(rgb - orange).max(axis=-1) <= 2).any()


def test_label_html_writes_the_takes_page(tmp_path):
    """label --html: one take's page, as batch writes per take, with its fills and links to its files."""
    pytest.importorskip("matplotlib", reason="matplotlib is not installed (pip install matplotlib)")
    takes = tmp_path / "takes"
    _synthetic(takes, 1, frames=600)
    page = tmp_path / "pages" / "synth0.html"
    page.parent.mkdir()
    assert main(["label", str(takes / "synth0.c3d"), "--layout", "han19", "-o", str(tmp_path / "l.c3d"), "--fill",
                 "--fill-method", "spline", "--html", str(page), "--quiet"]) == 0
    text = page.read_text()
    assert "<h1>synth0</h1>" in text and "<a href='../l.c3d'>" in text
    png = re.search(r"id='labels' alt='[^']*' src='data:image/png;base64,([^']+)'", text).group(1)
    assert _has_green(base64.b64decode(png)) > 0.2
    assert main(["label", str(takes / "synth0.c3d"), "--layout", "han19", "--html", str(tmp_path / "x.txt")]) == 2


def _queue_page(tmp_path):
    """A take's page of 300 frames from 101: one labeled segment in doubt on *4 (its slot's unlabeled samples
    are named *4 too), a long and a short unlabeled piece."""
    from mocap_autolabel.html_report import take_page

    segments = [  # as Labeling.summary() gives them, worst first
        {"slot": 7, "start": 10, "stop": 12, "frame_start": 111, "frame_end": 112, "label": None, "point": "*7",
         "confidence": 0.945},
        {"slot": 4, "start": 200, "stop": 240, "frame_start": 301, "frame_end": 340, "label": None, "point": "*4",
         "confidence": 0.949},
        {"slot": 4, "start": 50, "stop": 80, "frame_start": 151, "frame_end": 180, "label": "IndexTip",
         "point": "IndexTip", "confidence": 0.949},
    ]
    classes = np.full((3, 300), CONFIDENT, dtype=np.int8)
    classes[1, 50:80] = UNCERTAIN
    page = take_page({"name": "q", "summary": {"confident_share": 0.9, "uncertain_segments": segments}}, classes,
                     ["ThumbTip", "IndexTip", "MiddleTip"], 101)
    path = tmp_path / "q.html"
    path.write_text(page)
    return page, path


def test_the_pages_queue_names_trajectories_and_links_to_frames_the_picture_shows(tmp_path):
    """Issue 48: the page lists the review queue (labeled segments in doubt first, the short ghost left out),
    each entry naming its raw trajectory (*N, not the label again) and linking to #frames=A-B; the picture's
    data says where its axes are, so that the page's script can box those frames."""
    pytest.importorskip("matplotlib", reason="matplotlib is not installed (pip install matplotlib)")
    import matplotlib.image

    page, path = _queue_page(tmp_path)
    rows = re.findall(r"<tr data-frames='(\d+)-(\d+)'><td class='num'>(\d+)</td><td>(.*?)</td><td>(.*?)</td>", page)
    assert rows == [("151", "180", "1", "IndexTip", "*4"), ("301", "340", "2", "<i>unlabeled</i>", "*4")]
    assert "<a href='#frames=151-180'>151&ndash;180</a>" in page and "0.949 no marker" in page
    assert "Left out: 1 uncertain unlabeled pieces shorter than 10 frames" in page
    assert "<tr><th>to review</th><td>2 of 3 uncertain segments</td></tr>" in page
    # The axes' box in the picture: its left and right spines are dark columns at x0 and x1.
    img = re.search(r"<img id='labels'[^>]*>", page).group(0)
    data = {k: float(v) for k, v in re.findall(r"data-(\w+)='([-\d.]+)'", img)}
    assert data["first"] == 101 and data["frames"] == 300 and 0 < data["x0"] < data["x1"] < 1
    png = base64.b64decode(re.search(r"src='data:image/png;base64,([^']+)'", img).group(1))
    rgb = matplotlib.image.imread(io.BytesIO(png), format="png")[..., :3]
    h, w = rgb.shape[:2]

    def spines(line: np.ndarray, lo: float, hi: float) -> None:
        """Dark pixels (the spines) within 2 pixels of both ends, none between them (the plot is colour)."""
        dark = np.flatnonzero(line.max(axis=-1) < 0.2)
        assert np.abs(dark - lo).min() <= 2 and np.abs(dark - hi).min() <= 2
        assert not ((dark > lo + 2) & (dark < hi - 2)).any()

    spines(rgb[int(h * (data["y0"] + data["y1"]) / 2)], data["x0"] * w, data["x1"] * w)
    spines(rgb[:, int(w * (data["x0"] + data["x1"]) / 2)], data["y0"] * h, data["y1"] * h)


def test_a_frames_link_boxes_those_frames_in_a_browser(tmp_path):
    """In headless Chromium, opening the page at #frames=151-180 boxes frames 151-180 over the picture (the
    10 % of its axes from the 50th frame) and highlights that entry's row."""
    pytest.importorskip("matplotlib", reason="matplotlib is not installed (pip install matplotlib)")
    chromium = shutil.which("chromium") or shutil.which("chromium-browser")
    if chromium is None:
        pytest.skip("chromium is not installed (apt-get install chromium)")
    page, path = _queue_page(tmp_path)
    done = subprocess.run([chromium, "--headless", "--no-sandbox", "--disable-gpu", "--no-first-run",
                           f"--user-data-dir={tmp_path / 'chromium'}", "--dump-dom", path.as_uri() + "#frames=151-180"],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    style = re.search(r'<div id="span" style="([^"]*)"', done.stdout).group(1)
    box = {k: float(v) for k, v in re.findall(r"(left|width|top|height): ([-\d.]+)%", style)}
    assert "display: block" in style
    img = re.search(r"<img id='labels'[^>]*>", page).group(0)
    x0, x1 = (float(re.search(rf"data-{k}='([-\d.]+)'", img).group(1)) for k in ("x0", "x1"))
    assert box["left"] == pytest.approx(100 * (x0 + (x1 - x0) * 50 / 300), abs=0.01)
    assert box["width"] == pytest.approx(100 * (x1 - x0) * 30 / 300, abs=0.01)
    assert re.search(r'<tr data-frames="151-180" class="here">', done.stdout)


def test_the_index_links_pages_of_any_name_and_sorts_by_plain_numbers():
    """A trial's index held href='TAKE 14 é.report.html' unencoded and data-v='99.55000000000001'."""
    from mocap_autolabel.html_report import index_page

    page = index_page([{"name": "TAKE 14 é", "page": "TAKE 14 é.report.html", "status": "ok", "frames": 120,
                        "hands": 1, "confident_share": 0.9955, "uncertain_segments": 3, "marker_rms_mm": None}])
    assert "<a href='TAKE%2014%20%C3%A9.report.html'>TAKE 14 é</a>" in page
    assert "data-v='99.55'" in page and "99.55000000000001" not in page
